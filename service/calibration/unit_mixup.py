"""A column in another unit than the model declares for it: the failing sensor's readings, read again
in each other unit of the same dimension (°F for °C, kW for W, L/s for m³/s), against the model's
prediction of the test window. Where one such reading misses the prediction by at most a fifth of
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

import numpy as np

from service.data.measurements import MeasuredData
from service.graph.namespaces import local_name
from service.graph.units import QUDT_UNIT_NAMESPACE, QUDT_UNITS, convert, unit_label, unit_spec

__all__ = ["unit_mixups", "MIXUP_IMPROVEMENT", "TRACKING_SHARE"]

#: How many times smaller the RMSE read in the other unit must be than as declared.
MIXUP_IMPROVEMENT = 5.0
#: The RMSE read in the other unit, at most this share of the re-read readings' RMS magnitude.
TRACKING_SHARE = 0.2


def unit_mixups(data: MeasuredData, port_units: Mapping[str, str], observed: Mapping[str, np.ndarray],
                predictions: Sequence[Mapping[str, np.ndarray]], failing: Sequence[str]) -> list[str]:
    """One warning per sensor of ``failing`` (readings and predictions in its simulator unit
    ``port_units[node]``) whose test readings ``observed`` meet one of ``predictions`` (the calibrated
    model's, and the model's at its parameters' defaults, which a fit to the misread column has not
    bent) in another unit of its column's dimension (:data:`MIXUP_IMPROVEMENT`)."""
    warnings = []
    for node in failing:
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
