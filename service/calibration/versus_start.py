"""A model calibrated from another's estimates (``start_from``: the model with an effect added, started
from the model without it) against that model's run on the same data file and test window: a sensor the
new model fits worse is said, with the estimated parameters that moved furthest from the start.

Adding an effect frees no new freedom at a sensor it cannot reach, but the refit moves every estimated
parameter, and those the data do not identify drift along flat directions (a fan's curve), which a test
window with other operation shows (a fan power meter's error 14 → 22 W after a valve leak was added).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime

import numpy as np

from service.calibration.record import CalibrationRecord
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.graph.units import quantity_text
from service.model.assembled_model import AssembledModel
from service.model.wiring import parameter_label

__all__ = ["WORSE_RATIO", "worse_than_start"]

#: A sensor's test RMSE this many times its RMSE in the start's run (and over twice its noise) is worse.
WORSE_RATIO = 1.25
#: At most this many parameters are named, each moved by at least a twentieth of its prior range.
MOVED_NAMED, MOVED_SHARE = 3, 0.05


def worse_than_start(store: GraphStore, start_runs: Sequence[str], record: CalibrationRecord, model: AssembledModel,
                     start: np.ndarray, theta: np.ndarray) -> list[str]:
    """One warning per sensor whose test RMSE in ``record`` is :data:`WORSE_RATIO` times its RMSE in
    one of ``start_runs`` made on the same data file and test window (and over twice its noise), naming
    the parameters of ``model`` that moved furthest from ``start`` to ``theta`` (share of their range)."""
    if record.test_window is None:
        return []
    before: dict[str, tuple[float, str, str]] = {}  # sensor → (RMSE, unit, run)
    for run in start_runs:
        for row in store.run_named_query("run-test-rmse", run=run):
            same = (row["source"].value == record.data_source
                    and datetime.fromisoformat(row["test_start"].value) == record.test_window[0]
                    and datetime.fromisoformat(row["test_end"].value) == record.test_window[1])
            if same:
                before[row["sensor"].value] = (float(row["rmse"].value), row["unit"].value, run)
    worse = [(sensor, metrics.rmse, *before[sensor]) for sensor, metrics in record.metrics.get("test", {}).items()
             if sensor in before and metrics.rmse > WORSE_RATIO * before[sensor][0] and metrics.rmse > 2 * metrics.noise]
    if not worse:
        return []
    refs = model.estimated_parameters
    share = np.abs(np.asarray(theta) - np.asarray(start)) / np.array([r.spec.upper - r.spec.lower for r in refs])
    identified = {e.key: e.identified for e in record.estimates}
    sensor_of = {model.measurement(c).node: c for c in model.targets}
    reaches = {c: model.targets_reached_from([c]) for c in {r.component for r in refs}}

    def moved(sensor: str) -> list[str]:
        """The parameters of components upstream of ``sensor`` that moved furthest from the start."""
        upstream = [j for j, r in enumerate(refs) if sensor_of.get(sensor) in reaches[r.component]]
        return [f"{parameter_label(refs[j].key)} ({100 * share[j]:.0f} % of its range"
                + ("" if identified.get(refs[j].key, True) else ", not identified") + ")"
                for j in sorted(upstream, key=lambda j: -share[j])[:MOVED_NAMED] if share[j] >= MOVED_SHARE]

    return [f"{local_name(sensor)}: test RMSE {quantity_text(now, unit)}, against {quantity_text(was, unit)} in "
            f"{local_name(run)} of the model this one started from (same data and test window): fitted worse"
            + (f"; of the parameters upstream of it, these moved furthest from that start: {', '.join(names)}"
               if (names := moved(sensor)) else "")
            for sensor, now, was, unit, run in worse]
