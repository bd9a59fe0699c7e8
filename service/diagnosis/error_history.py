"""The test-window error of a model across its versions (``model``, ``model+Effect``, …), per sensor
and per operating regime: what ``graphtwin history``, the demo and the report page show so the user
sees the error fall, and where it fell."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.graph.units import difference_unit

__all__ = ["ErrorHistory", "error_history"]


@dataclass
class ErrorHistory:
    """``rmse[sensor][i]``: the test RMSE of ``versions[i]`` (NaN: not measured in that version), in
    ``units[sensor]`` (an error's unit: K for readings in °C);
    ``regime_rmse[rule][sensor][i]`` and ``regime_share[rule][i]`` the same per operating regime,
    regimes identified by their rule (versions calibrated on the same data share their regimes;
    a regime a version does not have is NaN there)."""

    versions: list[str]
    rmse: dict[str, list[float]]
    units: dict[str, str]
    regime_rmse: dict[str, dict[str, list[float]]]
    regime_share: dict[str, list[float]]
    tested_on: list[str]  # per version: the data file, test window and operating filter of its run
    regime_number: dict[str, str] = field(default_factory=dict)  # rule → its number in the newest run that has it

    @property
    def comparable(self) -> bool:
        """Whether every version was tested on the same data, window and operating filter
        (``--only-when``; else their errors differ by what they were tested on as much as by the model)."""
        return len(set(self.tested_on)) <= 1


def error_history(store: GraphStore, model: str) -> ErrorHistory:
    """The history of ``model`` without its ``+effect`` suffixes and every version derived from it
    (``model+Effect…``), each version's latest calibration with a test window
    (``queries/sensor-metrics.rq``, newest first)."""
    base = model.split("+", 1)[0]
    versions: list[str] = []
    rmse: dict[str, dict[str, float]] = {}
    units: dict[str, str] = {}
    regime_rmse: dict[str, dict[str, dict[str, float]]] = {}
    regime_share: dict[str, dict[str, float]] = {}
    regime_number: dict[str, str] = {}
    tested_on: list[str] = []
    for name in [m for m in store.models() if m == base or m.startswith(base + "+")]:
        newest_run, found = None, False
        for row in store.run_named_query("sensor-metrics", model=name):
            if row["window"].value != "test" or row["metric"].value != "rmse":
                continue
            newest_run = newest_run or row["run"]
            if row["run"] != newest_run:
                continue
            sensor, value = row["sensor"].value, float(row["value"].value)
            if "rule" in row:
                rule = row["rule"].value
                regime_rmse.setdefault(rule, {}).setdefault(sensor, {})[name] = value
                regime_share.setdefault(rule, {})[name] = float(row["share"].value)
                regime_number.setdefault(rule, local_name(row["regime"].value))
            else:
                rmse.setdefault(sensor, {})[name] = value
                units[sensor] = difference_unit(row["unit"].value)  # K for °C (runs stored before 2026-12-01)
                found = True
        if found:
            versions.append(name)
            [run] = store.query(_TESTED_ON, substitutions={"run": newest_run})
            only_when = json.loads(run["settings"].value).get("only_when", []) if "settings" in run else []
            tested_on.append(f"{run['source'].value}, {run['start'].value} – {run['end'].value}"
                             + (f", only when {' and '.join(only_when)}" if only_when else ""))

    def per_version(values: dict[str, float]) -> list[float]:
        return [values.get(v, float("nan")) for v in versions]

    return ErrorHistory(
        versions, {s: per_version(v) for s, v in rmse.items()}, units,
        {rule: {s: per_version(v) for s, v in sensors.items()} for rule, sensors in regime_rmse.items()},
        {rule: per_version(v) for rule, v in regime_share.items()}, tested_on, regime_number,
    )


_TESTED_ON = """PREFIX gt: <https://w3id.org/graphtwin/ontology#>
SELECT ?source ?start ?end ?settings WHERE {
  GRAPH ?g { ?run gt:dataSource ?source ; gt:testStart ?start ; gt:testEnd ?end OPTIONAL { ?run gt:settings ?settings } }
}"""
