"""A model's measured series: which columns it needs, in which unit, and how long its warm-up is.

Each measuring device needs a series in the simulator unit of its output's quantity (temperature
°C, volume flow m³/s, power W, position 1: :data:`QUANTITY_UNITS`); :func:`read_model_data` reads
them (:func:`service.data.measurements.read_measurements`) keyed by the devices' building-node IRIs.
Times in seconds: a window is warmed up over :func:`model_warmup_s` of the data before it (the
first :data:`WARMUP_PERIOD_S` repeated before the data's first step), its first :data:`SETTLING_S`
are not scored, nor :data:`GAP_RECOVERY_S` after a gap in a boundary input (``docs/data.md``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from service.data.measurements import MeasuredData, SeriesSpec, read_measurements
from service.errors import InputError, SignatureError
from service.graph.namespaces import local_name
from service.graph.units import convert
from service.matching.signature import QUANTITY_UNITS
from service.model.assembled_model import AssembledModel, mapped_values_outside_bounds

__all__ = ["GAP_RECOVERY_S", "SETTLING_S", "WARMUP_PERIOD_S", "device_unit", "series_specs",
           "check_mapped_parameters", "model_warmup_s", "model_start_memory_s", "warmup_period_steps",
           "read_model_data", "with_series_of"]

#: After a gap in a boundary input (held by the simulator), targets are not compared for this long [s]:
#: the model's states come out of the gap off (as at a window's start).
GAP_RECOVERY_S = 3600.0

#: Unscored start of every window [s]: the warm-up settles the model's states to the model's own
#: trajectory, not to the building's (longer where the warm-up is a guess: ``ModelData.unscored_start_s``).
SETTLING_S = 3600.0

#: Period repeated before the data's first step in a warm-up [s] (the first value held in data
#: shorter than this).
WARMUP_PERIOD_S = 86400.0


def device_unit(model: AssembledModel, component: str) -> str:
    """Simulator unit of the ``measured_value`` output of measuring device ``component``.

    :raises SignatureError: its signature gives that output no known quantity (naming the file).
    """
    instance = model.components[component]
    quantity = instance.signature.output_quantity("measured_value")
    if quantity not in QUANTITY_UNITS:
        raise SignatureError(f"{instance.signature.source_file}: measured_value output has no known quantity ({quantity!r})")
    return QUANTITY_UNITS[quantity]


def series_specs(model: AssembledModel) -> dict[str, SeriesSpec]:
    """Building-node IRI → what the model needs from its column (boundary inputs are required,
    targets too: a target without a column cannot be calibrated against)."""
    specs = {}
    for component in model.boundary_inputs + model.targets:
        link = model.measurement(component)
        specs[link.node] = SeriesSpec(link.node, link.series_id, link.unit, device_unit(model, component),
                                      holds_values=model.components[component].signature.holds_values,
                                      steps=model.components[component].signature.steps)
    return specs


def check_mapped_parameters(model: AssembledModel) -> None:
    """Refuse a model whose graph maps a parameter to a value outside its physical bounds (a typo or
    a wrong unit, which calibrating the other parameters around it would hide).

    :raises InputError: naming every such parameter, its node, the value and the bounds, in the
        parameter's unit.
    """
    problems = mapped_values_outside_bounds(model.mapped_parameters, model.components)
    if problems:
        raise InputError("; ".join(problems) + ": fix the value (or its unit) in the model graph")


def model_warmup_s(model: AssembledModel) -> float:
    """Warm-up simulated before every window of ``model`` [s]: its slowest component's settling time
    (:meth:`~service.components.component.ComponentModel.settling_time_s`: a day with a PI loop, none
    for static components), over the measured time before the window."""
    return max((c.model_class.settling_time_s() for c in model.components.values()), default=0.0)


def model_start_memory_s(model: AssembledModel) -> float:
    """How long ``model``'s outputs remember a wrong start state [s]: its components' longest
    :attr:`~service.components.component.ComponentModel.start_memory_s` (six hours with a PI loop)."""
    return max((c.model_class.start_memory_s for c in model.components.values()), default=0.0)


def warmup_period_steps(n_steps: int, step_s: float) -> int:
    """Steps of :data:`WARMUP_PERIOD_S` when data of ``n_steps`` cover it, else 1 (hold the first value)."""
    period = int(round(WARMUP_PERIOD_S / step_s))
    return period if n_steps >= period else 1


def with_series_of(data: MeasuredData, model: AssembledModel) -> tuple[MeasuredData, list[str]]:
    """``data`` with the series ``model`` needs and ``data`` lacks, taken from the file's columns that no
    device of the model it was read for claims (:attr:`MeasuredData.other_columns`, converted from the
    device's unit to its port unit): a room sensor that only an effect reads, left out of the base model.
    Also the columns the file lacks for ``model`` (``data`` unchanged where there is one)."""
    added: dict[str, tuple[np.ndarray, SeriesSpec, str]] = {}
    lacking = []
    for node, spec in series_specs(model).items():
        if node in data.series:
            continue
        column = next((name for name in spec.names() if name in data.other_columns), None)
        if column is None or spec.unit is None:
            lacking.append(spec.series_id or local_name(node))
        else:
            added[node] = (convert(data.other_columns[column], spec.unit, spec.port_unit), spec, column)
    if lacking or not added:
        return data, lacking
    return replace(data, series=data.series | {n: a[0] for n, a in added.items()},
                   units=data.units | {n: a[1].port_unit for n, a in added.items()},
                   columns=data.columns | {n: a[2] for n, a in added.items()},
                   source_units=data.source_units | {n: a[1].unit for n, a in added.items()}), []


def read_model_data(model: AssembledModel, path: Path | str, *, max_gap_steps: int = 5,
                    source_name: str | None = None) -> MeasuredData:
    """Read the CSV at ``path`` for ``model`` (:func:`service.data.measurements.read_measurements`;
    ``source_name``: what messages call the file)."""
    return read_measurements(path, series_specs(model), max_gap_steps=max_gap_steps, source_name=source_name)
