"""Operating filters: compare the model with the measurements only where it is meant to hold.

A condition is ``COLUMN OP VALUE [UNIT]``: a numeric column of the data file (by header or the
device's local name, ``_`` or spaces; also one the model does not read, a fan status), ``>``, ``>=``,
``<`` or ``<=`` (``≤``, ``≥``), and a number in that column's own unit (``"SF Spd Cmd (%) > 5"``), its
label after it if wished, checked (``"supply fan speed command ≤ 11 %"``, as a regime rule reads). The targets are compared where all
conditions hold; elsewhere the model is still simulated, but its targets' measurements enter neither
the calibration nor the metrics, regimes and episodes. A step where the column holds no number
fails the condition. Why: ``docs/data.md``, *Operating filters*.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from service.data.measurements import MeasuredData
from service.errors import InputError
from service.graph.units import UnitError, convert, unit_label, unit_spec

__all__ = ["OperatingCondition", "parse_condition", "operating_mask"]

_OPERATORS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}
_CONDITION = re.compile(r"^\s*(?P<column>.*?[^\s<>=≤≥])\s*(?P<op>>=|<=|>|<|≤|≥)\s*"
                        r"(?P<value>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)(?![\d.,eE])"
                        r"\s*(?P<unit>[^\s\d.,<>=≤≥][^<>=≤≥]*?)?\s*$")
_SYMBOLS = {"≤": "<=", "≥": ">="}  # as the regime rules print them


@dataclass(frozen=True)
class OperatingCondition:
    """``column op value``, ``value`` in the column's unit as written in the data file (``unit``: its
    label, if the condition states it, checked against the column's)."""

    column: str
    op: str
    value: float
    unit: str = ""

    def __str__(self) -> str:
        return f"{self.column} {self.op} {self.value:g}" + (f" {self.unit}" if self.unit else "")


def parse_condition(text: str) -> OperatingCondition:
    """``"SF Spd Cmd (%) > 5"`` → the condition.

    :raises InputError: naming the text and the expected form.
    """
    if re.search(r"\s(and|or)\s", text) and len(re.findall(r">=|<=|>|<|≤|≥", text)) > 1:
        either = re.search(r"\sor\s", text) is not None
        raise InputError(f"operating condition {text!r}: one condition per --only-when (a rule joined by 'and' is "
                         "one each; all must hold" + ("; a rule joined by 'or' is no filter of all-must-hold "
                                                  "conditions: give one of its bracketed branches" if either else "")
                         + ")")
    match = _CONDITION.match(text)
    if match is None:
        raise InputError(f"operating condition {text!r}: expected COLUMN OP NUMBER [UNIT] with OP one of >, >=, <, <= "
                         "(e.g. 'SF Spd Cmd (%) > 5')")
    op = _SYMBOLS.get(match["op"], match["op"])
    return OperatingCondition(match["column"], op, float(match["value"]), (match["unit"] or "").strip())


def _same_unit(text: str, unit: str) -> bool:
    """Whether ``text`` (a unit as a condition writes it: its label ``m³/s``, ``%``, or a unit name
    graphtwin reads, ``m3/s``, ``DEG_F``) is ``unit``."""
    if text == unit_label(unit):
        return True
    try:
        return unit_spec(text) == unit_spec(unit)
    except UnitError:
        return False


def _column_values(data: MeasuredData, condition: OperatingCondition) -> tuple[np.ndarray, float]:
    """The values ``condition``'s column holds and its threshold, in one unit: a column the model reads
    in its port unit (the threshold converted from the file's), another as the file gives it."""
    column = condition.column
    for node, header in data.columns.items():
        name = node.replace("#", "/").rsplit("/", 1)[-1]
        if column in (header.strip(), name, name.replace("_", " ")):  # the regime rules write names with spaces
            source_unit = data.source_units.get(node, data.units[node])
            if condition.unit and not _same_unit(condition.unit, source_unit):
                raise InputError(f"operating condition {condition}: the column {header.strip()!r} is in "
                                 f"{unit_label(source_unit) or 'a fraction'}, not {condition.unit} (give the number in "
                                 "the column's unit)")
            threshold = float(convert([condition.value], source_unit, data.units[node],
                                      where=f"operating condition {condition}")[0])
            return data.series[node], threshold
    if column in data.other_columns:
        if not np.isfinite(data.other_columns[column]).any():
            raise InputError(f"operating condition on {column!r}: that column of {data.source} holds no number")
        if condition.unit:
            raise InputError(f"operating condition {condition}: the model reads no unit for the column {column!r}; "
                             "give the number alone, in the column's unit as written in the file")
        return data.other_columns[column], condition.value
    known = ", ".join(sorted({h.strip() for h in data.columns.values()} | set(data.other_columns)))
    raise InputError(f"operating condition on {column!r}: {data.source} has no numeric column of that name "
                     f"(known: {known})")


def operating_mask(data: MeasuredData, conditions: Sequence[OperatingCondition | str]) -> np.ndarray:
    """``ndarray[n_steps]`` of bool: the steps where every condition holds (all steps for none).

    :raises InputError: a malformed condition or a column the file does not have (or holds no number in).
    """
    mask = np.ones(data.n_steps, dtype=bool)
    for condition in conditions:
        condition = parse_condition(condition) if isinstance(condition, str) else condition
        values, threshold = _column_values(data, condition)
        with np.errstate(invalid="ignore"):
            mask &= np.isfinite(values) & _OPERATORS[condition.op](values, threshold)
    if not mask.any():
        raise InputError(f"no step of {data.source} satisfies {' and '.join(map(str, conditions))}")
    return mask

