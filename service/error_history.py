"""The test-window error of a model across its versions (``model``, ``model+Effect``, …): what
``graphtwin history``, the demo and the report page show so the user sees the error fall."""

from __future__ import annotations

from .store import GraphStore


def error_history(store: GraphStore, model: str) -> tuple[list[str], dict[str, list[float]], dict[str, str]]:
    """(versions, test RMSE per sensor and version, unit per sensor) for ``model`` without its
    ``+effect`` suffixes and every version derived from it (``model+Effect…``), each version's
    latest calibration with a test window (``queries/sensor-metrics.rq``, newest first)."""
    base = model.split("+", 1)[0]
    versions: list[str] = []
    rmse: dict[str, dict[str, float]] = {}
    units: dict[str, str] = {}
    for name in [m for m in store.models() if m == base or m.startswith(base + "+")]:
        latest: dict[str, tuple[float, str]] = {}
        newest_run = None
        for row in store.run_named_query("sensor-metrics", model=name):
            if row["window"].value != "test" or row["metric"].value != "rmse":
                continue
            newest_run = newest_run or row["run"]
            if row["run"] == newest_run:
                latest[row["sensor"].value] = (float(row["value"].value), row["unit"].value)
        if latest:
            versions.append(name)
            for sensor, (value, unit) in latest.items():
                rmse.setdefault(sensor, {})[name] = value
                units[sensor] = unit
    return versions, {s: [v.get(n, float("nan")) for n in versions] for s, v in rmse.items()}, units
