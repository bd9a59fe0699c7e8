"""A calibration run written back as triples (PROV-O provenance, estimates, metrics, regimes).

All in the run's named graph ``gtr:graph/run/<id>`` (vocabulary in ``ontologies/graphtwin.ttl``):
the ``gt:CalibrationRun`` (``prov:Activity``: model, version, method, seed, data, windows, times,
settings, software agent), a ``gt:Estimate`` per parameter (median, 16/84 % quantiles, MAP,
standard error, bounds, identified), a ``gt:Metric`` per sensor, window and metric (and interval
level), a ``gt:OperatingRegime`` per regime with the test RMSE ``gt:inRegime`` it, and a Bayesian run's
``gt:PredictiveBand`` per sensor (its series as one JSON literal, :func:`band_json`). Parameter IRIs
are the assembly's (:func:`service.model.assembly_triples.parameter_iri`). The full shape:
``docs/calibration.md``, *Results as triples*.
"""

from __future__ import annotations

import json
import math
from datetime import datetime

import pyoxigraph as ox

from service import __version__
from service.calibration.metrics import on_interval_scale
from service.calibration.record import CalibrationDiagnostics, CalibrationRecord, PredictiveBand
from service.graph.namespaces import GT, GTR, PROV, RDF, RDFS, XSD, distinct_local_names
from service.graph.units import difference_unit

__all__ = ["run_iri", "calibration_triples", "software_agent", "band_json", "BAND_MAX_POINTS"]

#: Metrics written per sensor and window (attribute of :class:`~service.calibration.metrics.TargetMetrics`).
METRIC_ATTRIBUTES = ("rmse", "mae", "r2", "cv_rmse_percent", "nmbe_percent", "lag1_autocorrelation", "noise")
#: Points of a predictive band's series written at most (every ``stride``-th step; a figure is ~1200 px wide).
BAND_MAX_POINTS = 2000


def run_iri(run_id: str) -> ox.NamedNode:
    return ox.NamedNode(f"{GTR}run/{run_id}")


def software_agent() -> ox.NamedNode:
    return ox.NamedNode(f"{GTR}software/graphtwin/{__version__}")


def _double(value: float) -> ox.Literal:
    return ox.Literal(repr(float(value)), datatype=XSD.double)


def _time(value: datetime) -> ox.Literal:
    """``xsd:dateTime`` as the data's clock gives it: with its offset, or none for local time (a BMS
    export's naive stamps are not UTC, and saying so would shift them)."""
    return ox.Literal(value.isoformat(), datatype=XSD.dateTime)


def calibration_triples(record: CalibrationRecord, *, model_graph: str, assembly: str) -> list[ox.Triple]:
    """All triples of ``record``; non-finite numbers are left out (a NaN is no value)."""
    run = run_iri(record.run_id)
    agent = software_agent()
    t = [
        ox.Triple(run, RDF.type, GT.CalibrationRun),
        ox.Triple(run, RDF.type, PROV.Activity),
        ox.Triple(run, PROV.used, ox.NamedNode(model_graph)),
        ox.Triple(run, PROV.used, ox.NamedNode(assembly)),
        ox.Triple(run, GT.forModel, ox.Literal(record.model_name)),
        ox.Triple(run, GT.modelVersion, ox.Literal(record.model_version)),
        ox.Triple(run, GT.method, ox.Literal(record.method)),
        ox.Triple(run, GT.dataSource, ox.Literal(record.data_source)),
        ox.Triple(run, GT.trainStart, _time(record.train_window[0])),
        ox.Triple(run, GT.trainEnd, _time(record.train_window[1])),
        ox.Triple(run, PROV.startedAtTime, _time(record.started)),
        ox.Triple(run, PROV.endedAtTime, _time(record.finished)),
        ox.Triple(run, GT.settings, ox.Literal(json.dumps(record.settings, sort_keys=True, default=str))),
        ox.Triple(run, PROV.wasAssociatedWith, agent),
        ox.Triple(agent, RDF.type, PROV.SoftwareAgent),
        ox.Triple(agent, RDFS.label, ox.Literal(f"graphtwin {__version__}")),
        ox.Triple(run, RDFS.label, ox.Literal(f"{record.method} calibration of {record.model_name}")),
    ]
    if record.seed is not None:
        t.append(ox.Triple(run, GT.seed, ox.Literal(str(int(record.seed)), datatype=XSD.integer)))
    if record.test_window is not None:
        t += [ox.Triple(run, GT.testStart, _time(record.test_window[0])),
              ox.Triple(run, GT.testEnd, _time(record.test_window[1]))]
    t += _diagnostics_triples(run, record.diagnostics)
    for estimate in record.estimates:
        node = ox.NamedNode(f"{run.value}/estimate/{_component_slug(estimate.component)}/{estimate.name}")
        t += [
            ox.Triple(node, RDF.type, GT.Estimate),
            ox.Triple(node, PROV.wasGeneratedBy, run),
            ox.Triple(node, GT.ofParameter, ox.NamedNode(f"{estimate.component}/parameter/{estimate.name}")),
            ox.Triple(node, GT.onComponent, ox.NamedNode(estimate.component)),
            ox.Triple(node, GT.onNode, ox.NamedNode(estimate.node)),
            ox.Triple(node, GT.parameterName, ox.Literal(estimate.name)),
            ox.Triple(node, GT.unit, ox.Literal(estimate.unit)),
            ox.Triple(node, GT.identified, ox.Literal("true" if estimate.identified else "false", datatype=XSD.boolean)),
        ]
        for predicate, value in (
            (GT.median, estimate.median), (GT.quantile16, estimate.quantile16), (GT.quantile84, estimate.quantile84),
            (GT.map, estimate.map), (GT.standardError, estimate.standard_error),
            (GT.lowerBound, estimate.lower), (GT.upperBound, estimate.upper),
        ):
            if math.isfinite(value):
                t.append(ox.Triple(node, predicate, _double(value)))
        if estimate.reasons:
            t.append(ox.Triple(node, RDFS.comment, ox.Literal("; ".join(estimate.reasons))))
    sensor_name = distinct_local_names([*(n for per_sensor in record.metrics.values() for n in per_sensor),
                                        *(n for row in record.regimes for n in row["rmse"])])
    for window, per_sensor in record.metrics.items():
        for sensor, metrics in per_sensor.items():
            error_unit = difference_unit(metrics.unit)
            for attribute in METRIC_ATTRIBUTES:
                value = getattr(metrics, attribute)
                if not math.isfinite(value) or (attribute.endswith("percent") and on_interval_scale(metrics.unit)):
                    continue  # a ratio to the mean of readings in °C depends on the scale's zero
                unit = ("%" if attribute.endswith("percent") else
                        "1" if attribute in ("r2", "lag1_autocorrelation") else error_unit)
                t += _metric_triples(ox.NamedNode(f"{run.value}/metric/{window}/{sensor_name[sensor]}/{attribute}"),
                                     run, sensor, window, attribute, value, unit)
            for interval in metrics.coverage:
                for name, value, unit in (("coverage", interval.coverage, "1"), ("ace", interval.ace, "1"),
                                          ("mean_interval_width", interval.mean_width, error_unit)):
                    if math.isfinite(value):
                        node = ox.NamedNode(f"{run.value}/metric/{window}/{sensor_name[sensor]}/{name}/{interval.level:g}")
                        t += _metric_triples(node, run, sensor, window, name, value, unit)
                        t.append(ox.Triple(node, GT.intervalLevel, _double(interval.level)))
    units = {sensor: difference_unit(m.unit) for sensor, m in record.metrics.get("test", {}).items()}
    for row in record.regimes:
        regime = ox.NamedNode(f"{run.value}/regime/{row['regime']}")
        t += [ox.Triple(regime, RDF.type, GT.OperatingRegime), ox.Triple(regime, PROV.wasGeneratedBy, run),
              ox.Triple(regime, GT.regimeRule, ox.Literal(row["rule"])), ox.Triple(regime, GT.share, _double(row["share"]))]
        if math.isfinite(record.regime_rule_accuracy):
            t.append(ox.Triple(regime, GT.ruleAccuracy, _double(record.regime_rule_accuracy)))
        for sensor, value in row["rmse"].items():
            if not math.isfinite(value):
                continue
            node = ox.NamedNode(f"{run.value}/metric/test/{sensor_name[sensor]}/rmse/regime/{row['regime']}")
            t += _metric_triples(node, run, sensor, "test", "rmse", value, units.get(sensor, ""))
            t.append(ox.Triple(node, GT.inRegime, regime))
    for sensor, entries in record.discrepancy.items():  # the discrepancy GP's posterior medians, queryable as metrics
        for name, (median, _, _, unit) in entries.items():
            node = ox.NamedNode(f"{run.value}/metric/train/{sensor_name[sensor]}/gp_{name.replace(':', '/')}")
            t += _metric_triples(node, run, sensor, "train", f"gp_{name}", median, unit)
    for sensor, band in record.predictive_bands.items():
        node = ox.NamedNode(f"{run.value}/band/{band.window}/{sensor_name[sensor]}")
        t += [ox.Triple(node, RDF.type, GT.PredictiveBand), ox.Triple(node, PROV.wasGeneratedBy, run),
              ox.Triple(node, GT.onSensor, ox.NamedNode(sensor)), ox.Triple(node, GT.window, ox.Literal(band.window)),
              ox.Triple(node, GT.bandSeries, ox.Literal(band_json(band)))]
    return t


def band_json(band: PredictiveBand) -> str:
    """``{"level", "stride", "lower", "upper"}``: the band at every ``stride``-th step of its window
    (stride = ⌈n / BAND_MAX_POINTS⌉), 6 significant digits, NaN as null."""
    stride = max(1, math.ceil(band.lower.size / BAND_MAX_POINTS))

    def series(values) -> list[float | None]:
        return [float(f"{v:.6g}") if math.isfinite(v) else None for v in values[::stride].tolist()]

    return json.dumps({"level": band.level, "stride": stride, "lower": series(band.lower), "upper": series(band.upper)})


def _diagnostics_triples(run: ox.NamedNode, diagnostics: CalibrationDiagnostics) -> list[ox.Triple]:
    """What the run noticed: each warning (``gt:runWarning``), the point fit's least-squares cost, and
    how the Bayesian sampler ended (converged or not, IAT, steps, acceptance): an unconverged posterior
    is then told from a converged one by a query, not only in the terminal that ran it."""
    t = [ox.Triple(run, GT.runWarning, ox.Literal(warning)) for warning in diagnostics.warnings]
    if diagnostics.cost is not None and math.isfinite(diagnostics.cost):
        t.append(ox.Triple(run, GT.leastSquaresCost, _double(diagnostics.cost)))
    sampler = diagnostics.sampler
    if sampler is not None:
        t += [ox.Triple(run, GT.converged, ox.Literal("true" if sampler.converged else "false", datatype=XSD.boolean)),
              ox.Triple(run, GT.sampledSteps, ox.Literal(str(int(sampler.n_steps)), datatype=XSD.integer)),
              ox.Triple(run, GT.acceptanceFraction, _double(sampler.acceptance))]
        if math.isfinite(sampler.iat):
            t.append(ox.Triple(run, GT.integratedAutocorrelationTime, _double(sampler.iat)))
    return t


def _metric_triples(node: ox.NamedNode, run: ox.NamedNode, sensor: str, window: str, name: str, value: float,
                    unit: str) -> list[ox.Triple]:
    """One gt:Metric: ``name`` = ``value`` [``unit``] of ``sensor`` on ``window``, made by ``run``."""
    return [
        ox.Triple(node, RDF.type, GT.Metric),
        ox.Triple(node, PROV.wasGeneratedBy, run),
        ox.Triple(node, GT.onSensor, ox.NamedNode(sensor)),
        ox.Triple(node, GT.window, ox.Literal(window)),
        ox.Triple(node, GT.metricName, ox.Literal(name)),
        ox.Triple(node, GT.value, _double(value)),
        ox.Triple(node, GT.unit, ox.Literal(unit)),
    ]


def _component_slug(iri: str) -> str:
    """``…/component/Fan/supply_fan`` → ``Fan.supply_fan`` (unique within a model)."""
    return iri.split("/component/", 1)[-1].replace("/", ".")
