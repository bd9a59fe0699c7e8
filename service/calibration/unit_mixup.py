"""A column in another unit than the model declares for it: a target sensor's readings, read again
in each other unit of the same dimension (°F for °C, kW for W, L/s for m³/s), against the model's
prediction of the run's last window (the test window where there is one). Where one such reading
misses the prediction by at most a fifth of
the RMSE as declared, and by at most a fifth of its own magnitude (readings shrunk towards a
prediction near zero are not met), the column is probably in that unit (read in the wrong one of °C, °F and K a
temperature moves by tens of kelvin at least, a power or a flow by a factor of 2 or more): said as
a warning of the calibration, and so of every diagnosis (a BMS export in °F under a model that
says °C had been calibrated and diagnosed as a 46 K misfit no effect explains). The calibration has
bent the model towards the misread column, so the model at its parameters' defaults is asked too;
a meter the model has a free curve for can still hide it (fitted, it does not fail). A fraction
declared as percent, or the reverse, is caught when the data are read (``service.data.measurements``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from service.calibration.model_data import ModelData
from service.data.measurements import MeasuredData
from service.graph.namespaces import local_name
from service.graph.units import QUDT_UNIT_NAMESPACE, QUDT_UNITS, convert, unit_label, unit_spec
from service.model.assembled_model import AssembledModel

__all__ = ["unit_mixups", "inputs_off_scale", "temperature_inputs_misread", "MIXUP_IMPROVEMENT", "TRACKING_SHARE",
           "OFF_SCALE_ABOVE", "OFF_SCALE_BELOW", "REACH_SHARE"]

#: How many times smaller the RMSE read in the other unit must be than as declared.
MIXUP_IMPROVEMENT = 5.0
#: The RMSE read in the other unit, at most this share of the re-read readings' RMS magnitude.
TRACKING_SHARE = 0.2


def unit_mixups(data: MeasuredData, port_units: Mapping[str, str], observed: Mapping[str, np.ndarray],
                predictions: Sequence[Mapping[str, np.ndarray]]) -> list[str]:
    """One warning per sensor of ``observed`` (readings and predictions in its simulator unit
    ``port_units[node]``) whose readings meet one of ``predictions`` (the calibrated
    model's, and the model's at its parameters' defaults, which a fit to the misread column has not
    bent) in another unit of its column's dimension (:data:`MIXUP_IMPROVEMENT`)."""
    warnings = []
    for node in observed:
        declared, port = data.source_units.get(node), port_units[node]
        if declared is None:
            continue
        as_declared = unit_spec(declared)
        raw = convert(observed[node], port, declared)
        others = [name for name, spec in QUDT_UNITS.items()
                  if spec.dimension == as_declared.dimension and spec != as_declared and spec.label != "1"]
        found = None  # (the other unit, RMSE read in it, RMSE as declared)
        for predicted in predictions:
            mask = np.isfinite(raw) & np.isfinite(predicted[node])
            if mask.sum() < 2:
                continue
            rmse = float(np.sqrt(np.mean((observed[node][mask] - predicted[node][mask]) ** 2)))
            for name in others:
                reread = convert(raw[mask], QUDT_UNIT_NAMESPACE + name, port)
                alternative = float(np.sqrt(np.mean((reread - predicted[node][mask]) ** 2)))
                # met, not merely shrunk towards a prediction near zero (a flow re-read in a smaller unit)
                tracks = alternative <= TRACKING_SHARE * float(np.sqrt(np.mean(reread**2)))
                better = alternative * MIXUP_IMPROVEMENT <= rmse and tracks
                if better and (found is None or alternative / rmse < found[1] / found[2]):
                    found = (name, alternative, rmse)
        if found is not None:
            name, alternative, rmse = found
            label, other_label = unit_label(port), unit_label(QUDT_UNIT_NAMESPACE + name)
            warnings.append(
                f"column {data.columns.get(node, local_name(node))!r} ({local_name(node)}): read as {other_label} "
                f"instead of the {unit_label(declared)} the model declares, it would miss the model by "
                f"{alternative:.3g} {label} instead of {rmse:.3g} {label}: is it in {other_label}? (then declare its "
                f"unit as unit:{name})")
    return warnings


#: A flow or power boundary input whose 95th percentile lies beyond these multiples of the largest
#: nominal value of its dimension the graph states is off the plant's scale.
OFF_SCALE_ABOVE, OFF_SCALE_BELOW = 10.0, 1.0 / 50.0


def inputs_off_scale(data: MeasuredData, model: AssembledModel, node_of: Mapping[str, str]) -> list[str]:
    """One warning per boundary input (a flow or a power the model reads, not predicts) whose readings
    lie far off the scale the graph states for the plant: their 95th percentile beyond
    :data:`OFF_SCALE_ABOVE` times, or below :data:`OFF_SCALE_BELOW` of, the largest mapped nominal
    value of the same dimension (a fan's nominal flow), with the unit in which they would fit it (an
    air flow in m³/h declared as m³/s drives the model with 3,600 times the flow, which no parameter
    and no diagnosis can explain). ``node_of``: component IRI → its node."""
    warnings = []
    for component in model.boundary_inputs:
        node = node_of[component]
        declared, port = data.source_units.get(node), data.units.get(node)
        if declared is None or port is None or unit_spec(port).dimension not in ("volume_flow", "mass_flow", "power"):
            continue
        nominal = [(convert([ref.value], ref.spec.unit, port)[0], ref) for ref in model.mapped_parameters
                   if ref.value and unit_spec(ref.spec.unit).dimension == unit_spec(port).dimension]
        readings = np.abs(data.series[node][np.isfinite(data.series[node])])
        if not nominal or readings.size == 0:
            continue
        scale, ref = max(nominal, key=lambda pair: pair[0])
        high = float(np.quantile(readings, 0.95))
        if OFF_SCALE_BELOW * scale <= high <= OFF_SCALE_ABOVE * scale:
            continue
        raw = convert([high], port, declared)[0]
        # the unit that puts the readings' 95th percentile nearest the nominal value, within its scale
        reread = {name: convert([raw], QUDT_UNIT_NAMESPACE + name, port)[0] for name, spec in QUDT_UNITS.items()
                  if spec.dimension == unit_spec(declared).dimension and spec != unit_spec(declared)}
        fits = sorted((abs(np.log(value / scale)), name) for name, value in reread.items()
                      if OFF_SCALE_BELOW * scale <= value <= 2.0 * scale)
        label = unit_label(port)
        hint = (f": is it in {unit_label(QUDT_UNIT_NAMESPACE + fits[0][1])}? (then declare its unit as "
                f"unit:{fits[0][1]})" if fits else "")
        warnings.append(
            f"column {data.columns.get(node, local_name(node))!r} ({local_name(node)}): its readings reach {high:.3g} "
            f"{label} (95th percentile), {high / scale:.3g} times the {ref.spec.name} of "
            f"{local_name(model.components[ref.component].node)} the graph states ({scale:.3g} {label}){hint}")
    return warnings


#: A target whose prediction moves by less than this share of its scale (RMS) when an input is re-read
#: is not one the input reaches: its error, whatever it is, does not judge the re-reading.
REACH_SHARE = 0.1


def temperature_inputs_misread(md: ModelData, window: slice, scales: Mapping[str, float]) -> list[str]:
    """One warning per temperature boundary input (an air or water temperature, a set point: the graph
    does not say which scale fits it) that, read in another temperature unit, lets the model at its
    parameters' defaults meet the targets it reaches over ``window`` far better: their squared error
    Σₖ mean(((y − ŷ)/scaleₖ)²) falls :data:`MIXUP_IMPROVEMENT`² times or more (a target whose prediction
    moves by less than :data:`REACH_SHARE` of its scale is not reached). Outdoor air in °F declared as
    °C drives the model with air at 30–60 °C: every target it reaches misses by tens of kelvin, and no
    target's own column is the one to re-read. The best re-reading is taken first and the others judged
    with it (with the supply water in K, re-reading the set point in °F also helps: it shuts the valve).
    ``scales``: each target's scale (the calibration's)."""
    observed = md.observed(window)
    defaults = md.default_theta()[None, :]

    def predict(series: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {node: values[0] for node, values in replace(md, data=replace(md.data, series=dict(series)))
                .simulate_targets(window, defaults).items()}

    def squared_error(predicted: Mapping[str, np.ndarray], reached: Sequence[str]) -> float:
        total = 0.0
        for node in reached:
            finite = np.isfinite(observed[node]) & np.isfinite(predicted[node])
            if finite.any():
                total += float(np.mean(((observed[node][finite] - predicted[node][finite]) / scales[node]) ** 2))
        return total

    def reached(before: Mapping[str, np.ndarray], after: Mapping[str, np.ndarray]) -> list[str]:
        moved = {node: np.abs(after[node] - before[node]) for node in observed}
        return [node for node, change in moved.items()
                if np.isfinite(change).any() and np.sqrt(np.nanmean(change**2)) > REACH_SHARE * scales[node]]

    data = md.data
    rereadings = {}  # (node, other unit) → the column read in it, in the port unit
    for component in md.model.boundary_inputs:
        node = md.node_of[component]
        declared, port = data.source_units.get(node), data.units.get(node)
        if declared is None or port is None or unit_spec(port).dimension != "temperature":
            continue
        raw = convert(data.series[node], port, declared)
        rereadings |= {(node, name): convert(raw, QUDT_UNIT_NAMESPACE + name, port) for name, spec in QUDT_UNITS.items()
                       if spec.dimension == "temperature" and spec != unit_spec(declared)}
    series, current, warnings = dict(data.series), None, []
    while rereadings:
        current = predict(series) if current is None else current
        best = None  # (improvement, key, its prediction)
        for key, values in rereadings.items():
            trial = predict(series | {key[0]: values})
            targets = reached(current, trial)
            before, after = squared_error(current, targets), squared_error(trial, targets)
            ratio = before / after if after > 0 else np.inf
            if targets and ratio >= MIXUP_IMPROVEMENT**2 and (best is None or ratio > best[0]):
                best = (ratio, key, trial)
        if best is None:
            break
        improvement, (node, name), current = best
        other = unit_label(QUDT_UNIT_NAMESPACE + name)
        warnings.append(
            f"column {data.columns.get(node, local_name(node))!r} ({local_name(node)}), a boundary input: read as "
            f"{other} instead of the {unit_label(data.source_units[node])} the model declares, it lets the model "
            f"meet the targets it drives {np.sqrt(improvement):.3g} times closer (RMS over their scales, at the "
            f"parameters' defaults): is it in {other}? (then declare its unit as unit:{name})")
        series[node] = rereadings[(node, name)]
        rereadings = {key: values for key, values in rereadings.items() if key[0] != node}
    return warnings
