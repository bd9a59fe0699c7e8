"""Units: QUDT unit IRIs in the graph, SI inside the simulator.

A sensor declares its unit with a QUDT unit IRI (``saref:isMeasuredIn unit:DEG_F``); a model port
the unit it works in (``"degC"``, ``"kg/s"``, ``"1"`` …). Conversion is affine,
``value_port = (value · m_from + o_from − o_to) / m_to``, with QUDT's multiplier ``m`` and offset ``o``
to the SI unit of the dimension (K for temperatures); percent becomes the 0–1 fraction. The port unit
``"K"`` is a temperature *difference*: only the multipliers apply (1 °F of bias is 5/9 K); the QUDT
``unit:K`` stays absolute. Examples: ``docs/graph-store.md``, Units.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from service.errors import UnitError
from service.graph.spelling import one_edit_apart

__all__ = ["UnitError", "UnitSpec", "QUDT_UNITS", "PORT_UNITS", "convert", "unit_spec", "unit_label", "bracketed_unit",
           "quantity_text", "closest_unit_hint", "KNOWN_UNITS", "difference_unit", "difference_label",
           "difference_text",
           "logged_difference_text", "logged_scale_text"]

QUDT_UNIT_NAMESPACE = "http://qudt.org/vocab/unit/"


@dataclass(frozen=True)
class UnitSpec:
    """``si = value · multiplier + offset`` in the SI unit of ``dimension``; ``difference``: a
    difference of that quantity (offsets do not apply)."""

    dimension: str
    multiplier: float
    offset: float = 0.0
    label: str = ""
    difference: bool = False


_F_OFFSET = 459.67 * 5.0 / 9.0
#: QUDT unit local name → spec (multipliers and offsets as QUDT gives them).
QUDT_UNITS: dict[str, UnitSpec] = {
    "DEG_C": UnitSpec("temperature", 1.0, 273.15, "°C"),
    "DEG_F": UnitSpec("temperature", 5.0 / 9.0, _F_OFFSET, "°F"),
    "K": UnitSpec("temperature", 1.0, 0.0, "K"),
    "W": UnitSpec("power", 1.0, 0.0, "W"),
    "KiloW": UnitSpec("power", 1e3, 0.0, "kW"),
    "MegaW": UnitSpec("power", 1e6, 0.0, "MW"),
    "BTU_IT-PER-HR": UnitSpec("power", 0.29307107, 0.0, "BTU/h"),
    "M3-PER-SEC": UnitSpec("volume_flow", 1.0, 0.0, "m³/s"),
    "M3-PER-HR": UnitSpec("volume_flow", 1.0 / 3600.0, 0.0, "m³/h"),
    "L-PER-SEC": UnitSpec("volume_flow", 1e-3, 0.0, "L/s"),
    "L-PER-MIN": UnitSpec("volume_flow", 1e-3 / 60.0, 0.0, "L/min"),
    "FT3-PER-MIN": UnitSpec("volume_flow", 0.00047194745, 0.0, "cfm"),
    "GAL_US-PER-MIN": UnitSpec("volume_flow", 6.30901964e-5, 0.0, "gpm"),
    "KiloGM-PER-SEC": UnitSpec("mass_flow", 1.0, 0.0, "kg/s"),
    "KiloGM-PER-HR": UnitSpec("mass_flow", 1.0 / 3600.0, 0.0, "kg/h"),
    "PERCENT": UnitSpec("fraction", 0.01, 0.0, "%"),
    "UNITLESS": UnitSpec("fraction", 1.0, 0.0, "1"),
    "NUM": UnitSpec("fraction", 1.0, 0.0, "1"),
    "FRACTION": UnitSpec("fraction", 1.0, 0.0, "1"),
    "PA": UnitSpec("pressure", 1.0, 0.0, "Pa"),
    "KiloPA": UnitSpec("pressure", 1e3, 0.0, "kPa"),
    "BAR": UnitSpec("pressure", 1e5, 0.0, "bar"),
    "IN_H2O": UnitSpec("pressure", 249.08891, 0.0, "inH₂O"),
    "SEC": UnitSpec("time", 1.0, 0.0, "s"),
    "MIN": UnitSpec("time", 60.0, 0.0, "min"),
    "HR": UnitSpec("time", 3600.0, 0.0, "h"),
    "W-PER-K": UnitSpec("conductance", 1.0, 0.0, "W/K"),
    "KiloW-PER-K": UnitSpec("conductance", 1e3, 0.0, "kW/K"),
    "PER-K": UnitSpec("inverse_temperature", 1.0, 0.0, "1/K"),
}

#: Simulator port unit → spec. ``"K"`` on a port means a temperature *difference* (no offset).
PORT_UNITS: dict[str, UnitSpec] = {
    "degC": QUDT_UNITS["DEG_C"], "degF": QUDT_UNITS["DEG_F"],
    "K": UnitSpec("temperature", 1.0, 0.0, "K", difference=True), "1/K": QUDT_UNITS["PER-K"],
    "W": QUDT_UNITS["W"], "kW": QUDT_UNITS["KiloW"],
    "m3/s": QUDT_UNITS["M3-PER-SEC"], "m3/h": QUDT_UNITS["M3-PER-HR"], "L/s": QUDT_UNITS["L-PER-SEC"],
    "kg/s": QUDT_UNITS["KiloGM-PER-SEC"], "1": QUDT_UNITS["UNITLESS"], "%": QUDT_UNITS["PERCENT"],
    "Pa": QUDT_UNITS["PA"], "kPa": QUDT_UNITS["KiloPA"], "bar": QUDT_UNITS["BAR"],
    "s": QUDT_UNITS["SEC"], "h": QUDT_UNITS["HR"], "W/K": QUDT_UNITS["W-PER-K"],
}


def unit_spec(unit: str, *, where: str = "") -> UnitSpec:
    """A QUDT unit IRI (or its local name) or a port unit → its spec.

    :param where: what carries the unit (a port, a column), for the error message.
    :raises UnitError: naming the unit (and ``where``) and listing the known ones.
    """
    if unit in PORT_UNITS:
        return PORT_UNITS[unit]
    local = unit[len(QUDT_UNIT_NAMESPACE):] if unit.startswith(QUDT_UNIT_NAMESPACE) else unit
    if local in QUDT_UNITS:
        return QUDT_UNITS[local]
    known = KNOWN_UNITS if unit.startswith(QUDT_UNIT_NAMESPACE) else f"{KNOWN_UNITS}{_AND_PORT_UNITS}"
    raise UnitError(f"unknown unit {unit!r}{f' for {where}' if where else ''}{closest_unit_hint(unit)}{known}")


#: What an unknown unit's message ends with (a list of several such problems says it once); a unit
#: not written as a QUDT IRI (a signature's port) also lists the simulator's port units.
KNOWN_UNITS = f": graphtwin knows the QUDT units {', '.join(sorted(QUDT_UNITS))} (as {QUDT_UNIT_NAMESPACE}<name>)"
_AND_PORT_UNITS = f" and the port units {', '.join(sorted(PORT_UNITS))}"


def closest_unit_hint(unit: str) -> str:
    """`` (did you mean …/DEG_C?)`` for an unknown unit whose local name is a known QUDT unit's but
    for case, ``_`` and ``-`` (``DEGC``, ``deg_c``), else one with a letter added, dropped or two
    swapped (``DEG_CC``, ``KiloWW``; from four letters, where one slip reaches few); nothing
    otherwise (a letter replaced, ``DEG_K``, or a name merely close to one, ``L-PER-HR`` to
    ``M3-PER-HR``, is often another scale: no guess)."""
    local = unit.rsplit("/", 1)[-1]

    def bare(name: str) -> str:
        return name.replace("_", "").replace("-", "").lower()

    close = ([name for name in QUDT_UNITS if bare(name) == bare(local)][:1]
             or [name for name in QUDT_UNITS
                 if len(local) >= 4 and one_edit_apart(bare(name), bare(local), replaced=False)])
    return f" (did you mean {' or '.join(QUDT_UNIT_NAMESPACE + name for name in close)}?)" if close else ""


def difference_unit(unit: str) -> str:
    """The unit a difference of two readings in ``unit`` (an error, a residual, a noise σ) is stated
    in: ``"K"`` for °C (an error of 0.2 °C is one of 0.2 K), the unit itself otherwise (°F keeps its
    degree)."""
    try:
        spec = unit_spec(unit)
    except UnitError:
        return unit
    return "K" if spec.dimension == "temperature" and spec.offset and spec.multiplier == 1.0 else unit


def difference_label(unit: str) -> str:
    """:func:`unit_label` of :func:`difference_unit`: ``K`` for an error of readings in °C."""
    return unit_label(difference_unit(unit))


def difference_text(value: float | None, unit: str, logged_unit: str = "",
                    number: Callable[[float], str] = lambda v: format(v, ".3g")) -> str:
    """An error, residual or noise σ of readings in ``unit``, in its :func:`difference_unit`, and after it
    in the unit the readings were logged in (``logged_unit``, a column's) where their degrees differ:
    ``14.5 K (26.1 °F)``; a difference scales by the units' multipliers alone. ``number`` formats each
    value; a missing value (None, NaN) is ``–``."""
    if value is None or not np.isfinite(value):
        return "–"
    text = f"{number(value)} {unit_label(difference_unit(unit))}".rstrip()
    restated = logged_difference_text(value, unit, logged_unit, number)
    return f"{text} ({restated})" if restated else text


def logged_scale_text(unit: str, logged_unit: str) -> str | None:
    """What one unit of a difference of readings in ``unit`` is in the unit they were logged in:
    ``1 K = 1.8 °F``, ``1 = 100 %`` (None where :func:`logged_difference_text` gives none)."""
    logged = logged_difference_text(1.0, unit, logged_unit)
    return None if logged is None else f"{' '.join(filter(None, ['1', difference_label(unit)]))} = {logged}"


def logged_difference_text(value: float, unit: str, logged_unit: str,
                           number: Callable[[float], str] = lambda v: format(v, ".3g")) -> str | None:
    """A difference of readings in ``unit`` stated in the unit they were logged in (``1.8 °F`` for
    1 K of readings in °C logged in °F); None where the two units' degrees agree, their dimensions
    differ or either is unknown."""
    try:
        own, logged = unit_spec(difference_unit(unit)), unit_spec(logged_unit) if logged_unit else None
    except UnitError:
        return None
    if logged is None or logged.dimension != own.dimension or logged.multiplier == own.multiplier:
        return None
    return f"{number(value * own.multiplier / logged.multiplier)} {unit_label(difference_unit(logged_unit))}".rstrip()


def unit_label(unit: str) -> str:
    """Short label for reports (``°F``, ``m³/s``; nothing for a plain number, a fraction's ``1``);
    the unit text itself when unknown."""
    try:
        spec = unit_spec(unit)
    except UnitError:
        return unit
    return "" if spec.label == "1" else spec.label or unit


def quantity_text(value: float | None, unit: str, number_format: str = ".3g") -> str:
    """``0.162 °C``: ``value`` in ``number_format`` with its unit's label (:func:`unit_label`; a
    plain number shows none, not a trailing space); a missing value (None, NaN) as ``–``."""
    if value is None or not np.isfinite(value):
        return "–"
    label = unit_label(unit)
    number = format(value, number_format)
    return f"{number} {label}" if label else number


def bracketed_unit(unit: str) -> str:
    """An axis's unit, ``[°C]``; nothing for a plain number."""
    label = unit_label(unit)
    return f"[{label}]" if label else ""


def convert(values: Sequence[float] | np.ndarray, from_unit: str, to_unit: str, *, where: str = "") -> np.ndarray:
    """Convert ``values`` from ``from_unit`` to ``to_unit`` (each a QUDT IRI or a port unit).

    :param where: what is converted (a port, a column), for the error message.
    :raises UnitError: unknown unit, or different dimensions (°F into a kg/s port).
    """
    source, target = unit_spec(from_unit, where=where), unit_spec(to_unit, where=where)
    if source.dimension != target.dimension:
        context = f" for {where}" if where else ""
        raise UnitError(
            f"cannot convert {from_unit} ({source.dimension}) to {to_unit} ({target.dimension}){context}"
        )
    array = np.asarray(values, dtype=float)
    if source.difference or target.difference:
        return array * (source.multiplier / target.multiplier)
    return (array * source.multiplier + source.offset - target.offset) / target.multiplier
