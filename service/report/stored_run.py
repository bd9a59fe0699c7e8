"""What the store holds about a run: the calibration run ``gtr:run/<run_id>`` (provenance, estimates,
metrics, operating regimes, a Bayesian run's predictive bands; :mod:`service.calibration.triples`)
and the diagnosis based on it, if any (ranked effect candidates, failure locations;
:func:`service.diagnosis.report.diagnosis_triples`), read back by SPARQL (``queries/sensor-metrics.rq`` for the metrics)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from service.calibration.record import SamplerConvergence
from service.calibration.triples import run_iri
from service.components.component import bound_side
from service.errors import NotFoundError
from service.graph.namespaces import local_name
from service.graph.store import GraphStore

__all__ = ["StoredEstimate", "StoredBand", "stored_band", "StoredRun", "StoredCandidate", "StoredLocation",
           "StoredDiagnosis", "read_run", "read_diagnosis", "DIAGNOSIS_SUFFIX"]

#: A diagnosis graph's id is its base run's id with this suffix.
DIAGNOSIS_SUFFIX = "-diagnosis"

_PREFIXES = """PREFIX gt: <https://w3id.org/graphtwin/ontology#>
PREFIX prov: <http://www.w3.org/ns/prov#>
PREFIX rdfs: <http://www.w3.org/2000/01/rdf-schema#>
PREFIX dcterms: <http://purl.org/dc/terms/>
"""
_RUN_QUERY = _PREFIXES + """
SELECT ?model ?version ?method ?source ?train_start ?train_end ?test_start ?test_end ?ended ?settings
       ?converged ?iat ?steps ?acceptance WHERE { GRAPH ?g {
  ?run a gt:CalibrationRun ; gt:forModel ?model ; gt:modelVersion ?version ; gt:method ?method ;
       gt:dataSource ?source ; gt:trainStart ?train_start ; gt:trainEnd ?train_end ; prov:endedAtTime ?ended ;
       gt:settings ?settings .
  OPTIONAL { ?run gt:testStart ?test_start ; gt:testEnd ?test_end }
  OPTIONAL { ?run gt:converged ?converged ; gt:sampledSteps ?steps ; gt:acceptanceFraction ?acceptance }
  OPTIONAL { ?run gt:integratedAutocorrelationTime ?iat }
} }"""
_WARNINGS_QUERY = _PREFIXES + "SELECT ?warning WHERE { GRAPH ?g { ?run gt:runWarning ?warning } }"
_ESTIMATES_QUERY = _PREFIXES + """SELECT ?component ?name ?node ?unit ?identified ?median ?quantile16 ?quantile84
       ?lower ?upper ?reasons
WHERE { GRAPH ?g {
  ?estimate prov:wasGeneratedBy ?run ; gt:onComponent ?component ; gt:parameterName ?name ; gt:onNode ?node ;
            gt:unit ?unit ; gt:identified ?identified .
  OPTIONAL { ?estimate rdfs:comment ?reasons }
  OPTIONAL { ?estimate gt:lowerBound ?lower }
  OPTIONAL { ?estimate gt:upperBound ?upper }
  OPTIONAL { ?estimate gt:median ?median }
  OPTIONAL { ?estimate gt:quantile16 ?quantile16 }
  OPTIONAL { ?estimate gt:quantile84 ?quantile84 }
} } ORDER BY ?node ?name"""
_DIAGNOSIS_QUERY = _PREFIXES + """SELECT ?diagnosis ?summary WHERE { GRAPH ?g {
  ?diagnosis a gt:DiagnosisRun ; gt:basedOnCalibration ?run . OPTIONAL { ?diagnosis rdfs:comment ?summary }
} }"""
_NOT_APPLICABLE_QUERY = _PREFIXES + "SELECT ?reason WHERE { GRAPH ?g { ?diagnosis gt:notApplicable ?reason } }"
_CANDIDATES_QUERY = _PREFIXES + """
SELECT ?effect ?id ?label ?node ?rank ?significant ?explanation ?score ?p_value ?delta_bic ?improvement ?fit_z
       ?held_out_z WHERE {
  GRAPH ?g { ?candidate prov:wasGeneratedBy ?diagnosis ; gt:candidateEffect ?effect ; gt:onNode ?node ;
                        gt:rank ?rank ; gt:significant ?significant ; gt:explanation ?explanation .
    OPTIONAL { ?candidate gt:scoreStatistic ?score } OPTIONAL { ?candidate gt:pValue ?p_value }
    OPTIONAL { ?candidate gt:deltaBic ?delta_bic } OPTIONAL { ?candidate gt:testImprovement ?improvement }
    OPTIONAL { ?candidate gt:fitDistance ?fit_z } OPTIONAL { ?candidate gt:heldOutDistance ?held_out_z } }
  OPTIONAL { GRAPH <https://w3id.org/graphtwin/resource/graph/signatures/library> {
    ?effect dcterms:identifier ?id ; rdfs:label ?label } }
  OPTIONAL { GRAPH ?g { ?effect a gt:ParameterDrift ; dcterms:identifier ?id ; rdfs:label ?label } }
} ORDER BY ?rank"""
_LOOKALIKES_QUERY = _PREFIXES + """SELECT ?effect ?node ?separate WHERE { GRAPH ?g {
  ?candidate prov:wasGeneratedBy ?diagnosis ; gt:candidateEffect ?effect ; gt:onNode ?node ;
             gt:indistinguishableFrom ?answer . OPTIONAL { ?candidate gt:wouldSeparate ?separate } } }"""
_REGIMES_QUERY = _PREFIXES + """SELECT ?regime ?rule ?share WHERE { GRAPH ?g {
  ?regime a gt:OperatingRegime ; prov:wasGeneratedBy ?run ; gt:regimeRule ?rule ; gt:share ?share .
} }"""
_BANDS_QUERY = _PREFIXES + """SELECT ?sensor ?window ?series WHERE { GRAPH ?g {
  ?band a gt:PredictiveBand ; prov:wasGeneratedBy ?run ; gt:onSensor ?sensor ; gt:window ?window ;
        gt:bandSeries ?series .
} }"""
_LOCATIONS_QUERY = _PREFIXES + """SELECT ?location ?failing ?matching ?text ?suspect WHERE { GRAPH ?g {
  ?location a gt:FailureLocation ; prov:wasGeneratedBy ?diagnosis ; gt:failingSensor ?failing ; rdfs:comment ?text .
  OPTIONAL { ?location gt:matchingSensor ?matching }
  OPTIONAL { ?location gt:suspect ?suspect }
} } ORDER BY ?location ?suspect"""


def _float(row: Mapping, key: str) -> float:
    return float(row[key].value) if key in row else float("nan")


@dataclass(frozen=True, kw_only=True)
class StoredEstimate:
    """One parameter estimate of a run: ``median`` and the 16/84 % quantiles (NaN where not stored),
    in ``unit``; ``node`` the building node of its component."""

    name: str
    node: str
    unit: str
    identified: bool
    median: float
    quantile16: float
    quantile84: float
    lower: float = float("nan")  # the parameter's bounds (NaN where not stored)
    upper: float = float("nan")
    reasons: str = ""  # why the data do not identify it ("; "-joined)

    @property
    def at_bound(self) -> str:
        """``"lower"`` or ``"upper"`` where the estimate sits at that bound (within 1e-6 of the range),
        else ``""``: the data pushed it there, and the bound, not the data, set its value."""
        return bound_side(self.median, self.lower, self.upper, 1e-6)


@dataclass(frozen=True, kw_only=True)
class StoredBand:
    """A Bayesian run's stored posterior predictive band of one sensor on ``window``: its central
    ``level`` interval at every ``stride``-th step of the window (NaN where nothing was predicted)."""

    window: str
    level: float
    stride: int
    lower: np.ndarray
    upper: np.ndarray

    def at_every_step(self, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` at each of the window's ``n_steps`` steps, linear between stored steps."""
        stored = np.arange(self.lower.size) * self.stride
        steps = np.arange(n_steps)
        return np.interp(steps, stored, self.lower), np.interp(steps, stored, self.upper)


@dataclass
class StoredRun:
    """A calibration run as stored: provenance, estimates (``component#name`` → estimate), metrics
    (``metrics[window][sensor][metric] = value``, ``units[sensor]``) and the operating regimes of
    its test window (``{"regime", "rule", "share", "rmse": {sensor: value}}``, by regime number), and
    a Bayesian run's predictive ``bands`` (sensor → :class:`StoredBand`), how its sampler ended (None
    for a point fit or a run stored without it) and the run's ``warnings``."""

    run_id: str
    model: str
    version: str
    method: str
    data_source: str
    train: tuple[str, str]
    test: tuple[str, str] | None
    ended: str
    settings: dict
    estimates: dict[str, StoredEstimate]
    metrics: dict[str, dict[str, dict[str, float]]]
    units: dict[str, str]
    regimes: list[dict]
    bands: dict[str, StoredBand] = field(default_factory=dict)
    sampler: SamplerConvergence | None = None
    warnings: list[str] = field(default_factory=list)
    #: A Bayesian run's discrepancy GP per sensor: name (amplitude, noise, length_scale:<input>) → (median, unit).
    discrepancy: dict[str, dict[str, tuple[float, str]]] = field(default_factory=dict)


def stored_band(series: str, window: str) -> StoredBand:
    """The band of a ``gt:bandSeries`` JSON literal (:func:`service.calibration.triples.band_json`)."""
    stored = json.loads(series)

    def values(key: str) -> np.ndarray:
        return np.array([np.nan if v is None else v for v in stored[key]], dtype=float)

    return StoredBand(window=window, level=float(stored["level"]), stride=int(stored["stride"]),
                      lower=values("lower"), upper=values("upper"))


def _run_id(run_id: str) -> str:
    """The calibration run's id; a diagnosis graph's id (``<run>-diagnosis``) names its base run."""
    return run_id[: -len(DIAGNOSIS_SUFFIX)] if run_id.endswith(DIAGNOSIS_SUFFIX) else run_id


def _latest_runs_text(store: GraphStore, name: str) -> str:
    """``; …`` naming the latest runs of model ``name`` (a model's name given for a run id), or the
    store's latest runs (``queries/calibration-run-graphs.rq``, newest first)."""
    of_model = store.run_named_query("calibration-run-graphs", model=name)[:5]
    rows = of_model or store.run_named_query("calibration-run-graphs")[:5]
    if not rows:
        return " (it holds none)"

    def shown(row) -> str:
        run_id = row["run_id"].value
        return f"{run_id} (its diagnosis {run_id}{DIAGNOSIS_SUFFIX})" if "diagnosis_graph" in row else run_id

    whose = f"; {name!r} is a model, and its latest runs are" if of_model else "; the latest runs are"
    return f"{whose} {', '.join(shown(row) for row in rows)}"


def read_run(store: GraphStore, run_id: str) -> StoredRun:
    """The calibration run ``run_id`` (or the base run of diagnosis graph ``<run_id>-diagnosis``).

    :raises NotFoundError: no such run (also for an id that cannot name a run).
    """
    run_id = _run_id(run_id)
    try:
        run = run_iri(GraphStore.check_name(run_id))
    except ValueError:
        raise NotFoundError(f"no run {run_id!r}: not a run id") from None
    rows = store.query(_RUN_QUERY, substitutions={"run": run})
    if not rows:
        raise NotFoundError(f"no calibration run {run_id!r} in the store{_latest_runs_text(store, run_id)}")
    row = rows[0]
    estimates = {}
    for e in store.query(_ESTIMATES_QUERY, substitutions={"run": run}):
        estimates[f"{e['component'].value}#{e['name'].value}"] = StoredEstimate(
            name=e["name"].value, node=e["node"].value, unit=e["unit"].value,
            identified=e["identified"].value == "true", median=_float(e, "median"),
            quantile16=_float(e, "quantile16"), quantile84=_float(e, "quantile84"),
            lower=_float(e, "lower"), upper=_float(e, "upper"), reasons=e["reasons"].value if "reasons" in e else "",
        )
    metrics: dict[str, dict[str, dict[str, float]]] = {}
    units: dict[str, str] = {}
    discrepancy: dict[str, dict[str, tuple[float, str]]] = {}
    regimes = {r["regime"].value: {"regime": local_name(r["regime"].value), "rule": r["rule"].value,
                                   "share": float(r["share"].value), "rmse": {}}
               for r in store.query(_REGIMES_QUERY, substitutions={"run": run})}
    for m in store.run_named_query("sensor-metrics", model=row["model"].value):
        if m["run"] != run:
            continue
        sensor = m["sensor"].value
        if "regime" in m:
            regimes[m["regime"].value]["rmse"][sensor] = float(m["value"].value)
            continue
        if m["metric"].value.startswith("gp_"):  # the discrepancy GP's posterior median
            discrepancy.setdefault(sensor, {})[m["metric"].value[3:]] = (float(m["value"].value), m["unit"].value)
            continue
        metrics.setdefault(m["window"].value, {}).setdefault(sensor, {})[m["metric"].value] = float(m["value"].value)
        if m["metric"].value == "rmse":
            units[sensor] = m["unit"].value
    return StoredRun(
        run_id=run_id, model=row["model"].value, version=row["version"].value, method=row["method"].value,
        data_source=row["source"].value, train=(row["train_start"].value, row["train_end"].value),
        test=(row["test_start"].value, row["test_end"].value) if "test_start" in row else None,
        ended=row["ended"].value, settings=json.loads(row["settings"].value), estimates=estimates,
        metrics=metrics, units=units,
        regimes=sorted(regimes.values(), key=lambda r: int(r["regime"]) if r["regime"].isdigit() else r["regime"]),
        bands={b["sensor"].value: stored_band(b["series"].value, b["window"].value)
               for b in store.query(_BANDS_QUERY, substitutions={"run": run})},
        sampler=SamplerConvergence(row["converged"].value == "true", _float(row, "iat"), int(row["steps"].value),
                                   float(row["acceptance"].value)) if "converged" in row else None,
        warnings=sorted(w["warning"].value for w in store.query(_WARNINGS_QUERY, substitutions={"run": run})),
        discrepancy=discrepancy,
    )


@dataclass(frozen=True, kw_only=True)
class StoredCandidate:
    """One ranked effect candidate of a stored diagnosis (numbers NaN where not stored)."""

    effect: str
    label: str
    node: str
    rank: int
    significant: bool
    explanation: str
    score: float
    p_value: float
    delta_bic: float
    test_improvement: float
    effect_iri: str = ""
    indistinguishable: bool = False  # from the answer, on these data
    would_separate: tuple[str, ...] = ()
    fit_z: float = float("nan")  # a significant candidate told apart from the answer: how far its errors lie
    held_out_z: float = float("nan")  # from the answer's, in standard errors (fit windows, held-out half)


@dataclass(frozen=True, kw_only=True)
class StoredLocation:
    """One stored failure location: the failing sensor, the sensor upstream bounding the suspects
    (None when there is none), the sentence, and the suspect components."""

    failing: str
    matching: str | None
    text: str
    components: tuple[str, ...]


@dataclass
class StoredDiagnosis:
    """The diagnosis based on a run: its summary, ranked candidates and failure locations."""

    iri: str
    summary: str
    effects: list[StoredCandidate]
    locations: list[StoredLocation]
    not_applicable: tuple[str, ...] = ()  # why catalog effects were not tried

    @property
    def failing_sensors(self) -> set[str]:
        return {loc.failing for loc in self.locations}

    @property
    def suspects(self) -> set[str]:
        return {c for loc in self.locations for c in loc.components}

    @property
    def matching_sensors(self) -> set[str]:
        return {loc.matching for loc in self.locations if loc.matching}


def read_diagnosis(store: GraphStore, run_id: str) -> StoredDiagnosis | None:
    """The diagnosis whose ``gt:basedOnCalibration`` is run ``run_id``; None when there is none."""
    run = run_iri(_run_id(run_id))
    rows = store.query(_DIAGNOSIS_QUERY, substitutions={"run": run})
    if not rows:
        return None
    diagnosis = rows[0]["diagnosis"]
    bound = {"diagnosis": diagnosis}
    effects = [StoredCandidate(
        effect=r["id"].value if "id" in r else local_name(r["effect"].value), effect_iri=r["effect"].value,
        label=r["label"].value if "label" in r else "", node=r["node"].value, rank=int(r["rank"].value),
        significant=r["significant"].value == "true", explanation=r["explanation"].value,
        score=_float(r, "score"), p_value=_float(r, "p_value"), delta_bic=_float(r, "delta_bic"),
        test_improvement=_float(r, "improvement"), fit_z=_float(r, "fit_z"), held_out_z=_float(r, "held_out_z"),
    ) for r in store.query(_CANDIDATES_QUERY, substitutions=bound)]
    lookalikes: dict[tuple[str, str], list[str]] = {}
    for r in store.query(_LOOKALIKES_QUERY, substitutions=bound):
        texts = lookalikes.setdefault((r["effect"].value, r["node"].value), [])
        if "separate" in r:
            texts.append(r["separate"].value)
    effects = [replace(e, indistinguishable=True, would_separate=tuple(sorted(lookalikes[key])))
               if (key := (e.effect_iri, e.node)) in lookalikes else e for e in effects]
    suspects: dict[str, tuple[Mapping, list[str]]] = {}  # location IRI → (its first row, its suspects)
    for r in store.query(_LOCATIONS_QUERY, substitutions=bound):
        _, components = suspects.setdefault(r["location"].value, (r, []))
        if "suspect" in r:
            components.append(r["suspect"].value)
    locations = [StoredLocation(failing=r["failing"].value, matching=r["matching"].value if "matching" in r else None,
                                text=r["text"].value, components=tuple(components))
                 for r, components in suspects.values()]
    not_applicable = tuple(sorted(r["reason"].value for r in store.query(_NOT_APPLICABLE_QUERY, substitutions=bound)))
    return StoredDiagnosis(diagnosis.value, rows[0]["summary"].value if "summary" in rows[0] else "",
                           effects, locations, not_applicable)
