"""A run's report: one self-contained HTML page built from what the store holds about the run.

``report_html(store, run_id)`` reads the calibration run ``gtr:run/<run_id>`` (provenance, estimates,
metrics, operating regimes; :mod:`service.calibration.triples`) and the diagnosis based on it, if
any (ranked effect candidates, failure locations; :func:`service.diagnosis.loop.diagnosis_triples`), and
shows:

1. per sensor: the stored metrics and a figure of measured against modelled with an interval;
2. the flow-path localisation drawn on the system topology (``queries/flow-edges.rq``,
   ``observed-node.rq``): the suspects between the last matching and the first failing sensor;
3. the operating regimes with their rules and the test RMSE per sensor in each;
4. the ranked missing effects with their evidence;
5. the test RMSE per sensor, overall and per regime, across the model's versions
   (``queries/sensor-metrics.rq``).

**Series.** A run stores numbers, not series. The measured-vs-model figures are recomputed: the
model graph (whose version must still be the run's ``gt:modelVersion``) is assembled again, the
run's data file (``gt:dataSource``, found by the caller's ``locate_data``) is read, and the model is
simulated at the stored estimates (``gt:median``) over the stored windows with the stored sub-steps,
as :func:`service.calibration.run.predict_test` does. The page says so when this is impossible
(data file not found, model changed) and flags a recomputed test RMSE that differs from the stored
one by more than ``REPRODUCTION_TOLERANCE``. The interval is the 90 % prediction interval of
independent normal residuals with the training window's stored RMSE s: ŷ ± z₀.₉₅·s, z₀.₉₅ = 1.645
(a run stores no predictive interval series; parameter correlations are not stored either).

Everything is in the page: the figures are base64 PNG (matplotlib, :mod:`service.report.plots`) or SVG
``<img>`` data URIs, the style is inline, there is no script, and a Content-Security-Policy that
allows only ``data:`` images makes the browser refuse anything from elsewhere.
"""

from __future__ import annotations

import base64
import html
import json
import tempfile
from collections import defaultdict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from statistics import NormalDist

import numpy as np

from service.model.assembly import assemble
from service.calibration.model_data import ModelData, read_model_data
from service.calibration.run import model_version, predict_test
from service.calibration.triples import run_iri
from service.diagnosis.error_history import error_history
from service.diagnosis.localization import FlowTopology
from service.graph.namespaces import GTR, local_name
from service.data.operating_filter import operating_mask
from service.graph.store import GraphStore
from service.graph.units import unit_label

__all__ = [
    "UnknownRunError", "StoredRun", "StoredDiagnosis", "RunSeries", "read_run", "read_diagnosis",
    "recompute_series", "topology_svg", "report_html", "data_file_locator",
    "INTERVAL_LEVEL", "REPRODUCTION_TOLERANCE", "CONTENT_SECURITY_POLICY",
]

#: Two-sided level of the prediction interval drawn around the model.
INTERVAL_LEVEL = 0.90
#: Relative difference between the recomputed and the stored test RMSE above which the page warns.
REPRODUCTION_TOLERANCE = 0.01
#: Standard normal quantile of the interval's upper end (1.645 for 90 %).
_Z = NormalDist().inv_cdf(0.5 + INTERVAL_LEVEL / 2)
DIAGNOSIS_SUFFIX = "-diagnosis"
#: Only inline styles and ``data:`` images: the browser refuses anything else (no request leaves the page).
CONTENT_SECURITY_POLICY = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"

_PREFIXES = """PREFIX gt: <https://w3id.org/graphtwin/ontology#>
PREFIX prov: <http://www.w3.org/ns/prov#>
PREFIX rdfs: <http://www.w3.org/2000/01/rdf-schema#>
PREFIX dcterms: <http://purl.org/dc/terms/>
"""
_RUN_QUERY = _PREFIXES + """
SELECT ?model ?version ?method ?source ?train_start ?train_end ?test_start ?test_end ?ended ?settings WHERE { GRAPH ?g {
  ?run a gt:CalibrationRun ; gt:forModel ?model ; gt:modelVersion ?version ; gt:method ?method ;
       gt:dataSource ?source ; gt:trainStart ?train_start ; gt:trainEnd ?train_end ; prov:endedAtTime ?ended ;
       gt:settings ?settings .
  OPTIONAL { ?run gt:testStart ?test_start ; gt:testEnd ?test_end }
} }"""
_ESTIMATES_QUERY = _PREFIXES + """SELECT ?component ?name ?node ?unit ?identified ?median ?quantile16 ?quantile84
WHERE { GRAPH ?g {
  ?estimate prov:wasGeneratedBy ?run ; gt:onComponent ?component ; gt:parameterName ?name ; gt:onNode ?node ;
            gt:unit ?unit ; gt:identified ?identified .
  OPTIONAL { ?estimate gt:median ?median }
  OPTIONAL { ?estimate gt:quantile16 ?quantile16 }
  OPTIONAL { ?estimate gt:quantile84 ?quantile84 }
} } ORDER BY ?node ?name"""
_DIAGNOSIS_QUERY = _PREFIXES + """SELECT ?diagnosis ?summary WHERE { GRAPH ?g {
  ?diagnosis a gt:DiagnosisRun ; gt:basedOnCalibration ?run . OPTIONAL { ?diagnosis rdfs:comment ?summary }
} }"""
_CANDIDATES_QUERY = _PREFIXES + """
SELECT ?effect ?id ?label ?node ?rank ?significant ?explanation ?score ?p_value ?delta_bic ?improvement WHERE {
  GRAPH ?g { ?candidate prov:wasGeneratedBy ?diagnosis ; gt:candidateEffect ?effect ; gt:onNode ?node ;
                        gt:rank ?rank ; gt:significant ?significant ; gt:explanation ?explanation .
    OPTIONAL { ?candidate gt:scoreStatistic ?score } OPTIONAL { ?candidate gt:pValue ?p_value }
    OPTIONAL { ?candidate gt:deltaBic ?delta_bic } OPTIONAL { ?candidate gt:testImprovement ?improvement } }
  OPTIONAL { GRAPH <https://w3id.org/graphtwin/resource/graph/signatures/library> {
    ?effect dcterms:identifier ?id ; rdfs:label ?label } }
} ORDER BY ?rank"""
_REGIMES_QUERY = _PREFIXES + """SELECT ?regime ?rule ?share WHERE { GRAPH ?g {
  ?regime a gt:OperatingRegime ; prov:wasGeneratedBy ?run ; gt:regimeRule ?rule ; gt:share ?share .
} }"""
_LOCATIONS_QUERY = _PREFIXES + """SELECT ?location ?failing ?matching ?text ?suspect WHERE { GRAPH ?g {
  ?location a gt:FailureLocation ; prov:wasGeneratedBy ?diagnosis ; gt:failingSensor ?failing ; rdfs:comment ?text .
  OPTIONAL { ?location gt:matchingSensor ?matching }
  OPTIONAL { ?location gt:suspect ?suspect }
} } ORDER BY ?location ?suspect"""


class UnknownRunError(KeyError):
    """No calibration run with this id in the store."""

    def __str__(self) -> str:
        return str(self.args[0])


def _float(row: Mapping, key: str) -> float:
    return float(row[key].value) if key in row else float("nan")


# ====================================================================== what the store holds
@dataclass
class StoredRun:
    """A calibration run as stored: provenance, estimates (``component#name`` → dict), metrics
    (``metrics[window][sensor][metric] = value``, ``units[sensor]``) and the operating regimes of
    its test window (``{"regime", "rule", "share", "rmse": {sensor: value}}``, by regime number)."""

    run_id: str
    model: str
    version: str
    method: str
    data_source: str
    train: tuple[str, str]
    test: tuple[str, str] | None
    ended: str
    settings: dict
    estimates: dict[str, dict]
    metrics: dict[str, dict[str, dict[str, float]]]
    units: dict[str, str]
    regimes: list[dict]


def _run_id(run_id: str) -> str:
    """The calibration run's id; a diagnosis graph's id (``<run>-diagnosis``) names its base run."""
    return run_id[: -len(DIAGNOSIS_SUFFIX)] if run_id.endswith(DIAGNOSIS_SUFFIX) else run_id


def read_run(store: GraphStore, run_id: str) -> StoredRun:
    """The calibration run ``run_id`` (or the base run of diagnosis graph ``<run_id>-diagnosis``).

    :raises UnknownRunError: no such run (also for an id that cannot name a run).
    """
    run_id = _run_id(run_id)
    try:
        run = run_iri(GraphStore.check_name(run_id))
    except ValueError:
        raise UnknownRunError(f"no run {run_id!r}: not a run id") from None
    rows = store.query(_RUN_QUERY, substitutions={"run": run})
    if not rows:
        raise UnknownRunError(f"no calibration run {run_id!r} in the store")
    row = rows[0]
    estimates = {}
    for e in store.query(_ESTIMATES_QUERY, substitutions={"run": run}):
        estimates[f"{e['component'].value}#{e['name'].value}"] = {
            "name": e["name"].value, "node": e["node"].value, "unit": e["unit"].value,
            "identified": e["identified"].value == "true", "median": _float(e, "median"),
            "quantile16": _float(e, "quantile16"), "quantile84": _float(e, "quantile84"),
        }
    metrics: dict[str, dict[str, dict[str, float]]] = {}
    units: dict[str, str] = {}
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
    )


@dataclass
class StoredDiagnosis:
    """The diagnosis based on a run: its summary, ranked candidates and failure locations."""

    iri: str
    summary: str
    effects: list[dict]
    locations: list[dict]

    @property
    def failing_sensors(self) -> set[str]:
        return {loc["failing"] for loc in self.locations}

    @property
    def suspects(self) -> set[str]:
        return {c for loc in self.locations for c in loc["components"]}

    @property
    def matching_sensors(self) -> set[str]:
        return {loc["matching"] for loc in self.locations if loc["matching"]}


def read_diagnosis(store: GraphStore, run_id: str) -> StoredDiagnosis | None:
    """The diagnosis whose ``gt:basedOnCalibration`` is run ``run_id``; None when there is none."""
    run = run_iri(_run_id(run_id))
    rows = store.query(_DIAGNOSIS_QUERY, substitutions={"run": run})
    if not rows:
        return None
    diagnosis = rows[0]["diagnosis"]
    bound = {"diagnosis": diagnosis}
    effects = [{
        "effect": r["id"].value if "id" in r else local_name(r["effect"].value),
        "label": r["label"].value if "label" in r else "", "node": r["node"].value, "rank": int(r["rank"].value),
        "significant": r["significant"].value == "true", "explanation": r["explanation"].value,
        "score": _float(r, "score"), "p_value": _float(r, "p_value"), "delta_bic": _float(r, "delta_bic"),
        "test_improvement": _float(r, "improvement"),
    } for r in store.query(_CANDIDATES_QUERY, substitutions=bound)]
    locations: dict[str, dict] = {}
    for r in store.query(_LOCATIONS_QUERY, substitutions=bound):
        loc = locations.setdefault(r["location"].value, {
            "failing": r["failing"].value, "matching": r["matching"].value if "matching" in r else None,
            "text": r["text"].value, "components": []})
        if "suspect" in r:
            loc["components"].append(r["suspect"].value)
    return StoredDiagnosis(diagnosis.value, rows[0]["summary"].value if "summary" in rows[0] else "",
                           effects, list(locations.values()))


# ====================================================================== series, recomputed
@dataclass
class RunSeries:
    """Measured and modelled series of one window (``window`` is ``"test"`` or ``"train"``), each
    target node's interval ``band[node] = (low, high)``, the recomputed RMSE, and ``notes``."""

    window: str
    timestamps: np.ndarray
    observed: dict[str, np.ndarray]
    predicted: dict[str, np.ndarray]
    band: dict[str, tuple[np.ndarray, np.ndarray]]
    rmse: dict[str, float]
    units: dict[str, str]
    notes: list[str] = field(default_factory=list)


def recompute_series(store: GraphStore, run: StoredRun, data_path: Path) -> RunSeries:
    """Simulate the run's model at its stored estimates over its test window (else its training
    window), the test window as the continuation of the training run.

    :raises ValueError: the model graph changed since the run, an estimate is missing, or the data
        do not cover the run's windows (each message says which).
    """
    if not store.has_model(run.model):
        raise ValueError(f"model {run.model} is no longer in the store: the run's series cannot be simulated again")
    current = model_version(store, run.model)
    if current != run.version:
        raise ValueError(f"model {run.model} is now version {current}, the run calibrated version {run.version}: "
                         "its series cannot be recomputed")
    model = assemble(store, run.model)
    data = read_model_data(model, data_path)
    md = ModelData(model, data, int(run.settings["substeps"]), operating_mask(data, run.settings.get("only_when", [])),
                   warmup_s=run.settings.get("warmup_s", 0.0))  # a run stored before warm-ups was simulated cold
    missing = [ref.key for ref in model.estimated_parameters if ref.key not in run.estimates]
    if missing:
        raise ValueError(f"run {run.run_id} stores no estimate of {', '.join(missing)}")
    theta = np.array([run.estimates[ref.key]["median"] for ref in model.estimated_parameters])
    train = data.window(*run.train)
    if run.test is not None:
        name, window = "test", data.window(*run.test)
        predicted = predict_test(md, train, window, theta)
    else:
        name, window = "train", train
        predicted = {node: values[0] for node, values in md.simulate_targets(train, theta[None, :]).items()}
    observed = {node: np.where(np.isfinite(predicted[node]), values, np.nan)
                for node, values in md.observed(window).items()}
    band, rmse, notes = {}, {}, []
    for node, values in predicted.items():
        s = run.metrics.get("train", {}).get(node, {}).get("rmse", float("nan"))
        band[node] = (values - _Z * s, values + _Z * s)
        finite = np.isfinite(observed[node]) & np.isfinite(values)
        rmse[node] = float(np.sqrt(np.mean((observed[node][finite] - values[finite]) ** 2)))
        stored = run.metrics.get(name, {}).get(node, {}).get("rmse")
        if stored is not None and abs(rmse[node] - stored) > REPRODUCTION_TOLERANCE * stored:
            notes.append(f"{local_name(node)}: the recomputed {name} RMSE {rmse[node]:.4g} differs from the stored "
                         f"{stored:.4g}" + (" (a Bayesian run stores the predictive median's error; the figure "
                                            "simulates the posterior median parameters)" if run.method == "bayes"
                                            else ": the data file is not the one the run used"))
    return RunSeries(name, data.timestamps[window], observed, predicted, band, rmse, dict(md.units), notes)


def data_file_locator(explicit: Path | None = None, folder: Path | None = None) -> Callable[[str], Path]:
    """For the command line: ``explicit`` when given, else the run's recorded file name in ``folder``
    (the current folder by default). The locator raises FileNotFoundError naming what it tried."""

    def locate(source: str) -> Path:
        path = explicit if explicit is not None else (folder or Path.cwd()) / Path(source).name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such file (the run used {source!r}; give its path with --data)")
        return path

    return locate


# ====================================================================== topology drawing
_CHAR_PX, _LINE_PX, _BOX_H, _ROW_PX, _GAP_PX, _MARGIN, _LABEL_CHARS = 6.7, 13, 34, 50, 40, 16, 20


def _layers(nodes: list[str], downstream: Mapping[str, set[str]]) -> tuple[dict[str, int], set[tuple[str, str]]]:
    """Layer of each node (longest path from a source after cutting the loops' back edges, found by
    depth-first search from the sources in name order) and the back edges."""
    state: dict[str, int] = {}
    back: set[tuple[str, str]] = set()

    def visit(node: str) -> None:
        state[node] = 1
        for nxt in sorted(downstream.get(node, ())):
            if state.get(nxt) == 1:
                back.add((node, nxt))
            elif nxt not in state:
                visit(nxt)
        state[node] = 2

    has_upstream = {m for n in nodes for m in downstream.get(n, ())}
    for node in [n for n in nodes if n not in has_upstream] + nodes:
        if node not in state:
            visit(node)
    layer = {n: 0 for n in nodes}
    for _ in nodes:  # longest path by relaxation; the graph without back edges is acyclic
        changed = False
        for n in nodes:
            for m in downstream.get(n, ()):
                if (n, m) not in back and layer[m] < layer[n] + 1:
                    layer[m], changed = layer[n] + 1, True
        if not changed:
            break
    return layer, back


def _label_lines(iri: str, width: int = _LABEL_CHARS) -> list[str]:
    """The node's local name, wrapped at underscores into lines of at most ``width`` characters."""
    lines: list[str] = []
    for word in local_name(iri).split("_"):
        if lines and len(lines[-1]) + 1 + len(word) <= width:
            lines[-1] += "_" + word
        else:
            lines.append(word)
    return lines


def topology_svg(
    topology: FlowTopology, sensors: set[str], *, suspects: set[str] = frozenset(),
    failing: set[str] = frozenset(), matching: set[str] = frozenset(), heat_edges: set[tuple[str, str]] = frozenset(),
) -> str:
    """The flow topology as an SVG document: nodes in columns along the flow (left to right), fluid
    edges solid, heat edges dashed, loop edges curved back underneath; a sensor off the flow path sits
    below the node it observes, joined by a dotted line. Suspects are drawn red, failing sensors with
    a red border, matching sensors with a green one (``class`` attributes ``suspect``, ``failing``,
    ``matching`` and ``data-node`` say the same for machines)."""
    flow_nodes = sorted(set(topology.downstream) | set(topology.upstream))
    layer, back = _layers(flow_nodes, topology.downstream)
    off_path = sorted(sensors - set(flow_nodes))
    for sensor in off_path:
        layer[sensor] = layer.get(topology.place(sensor), 0)
    row: dict[str, int] = {}
    columns: dict[int, list[str]] = defaultdict(list)
    for index in sorted(set(layer.values())):
        taken: set[int] = set()

        def put(node: str, want: int) -> None:
            while want in taken:
                want += 1
            taken.add(want)
            row[node] = want
            columns[index].append(node)

        in_path = [n for n in flow_nodes if layer[n] == index]
        wants = {n: [row[u] for u in topology.upstream.get(n, ()) if u in row] for n in in_path}
        for n in sorted(in_path, key=lambda n: (float(np.mean(wants[n])) if wants[n] else 0.0, n)):
            put(n, int(round(float(np.mean(wants[n])))) if wants[n] else 0)
        for sensor in (s for s in off_path if layer[s] == index):
            owner = topology.place(sensor)
            put(sensor, row[owner] + 1 if owner in row else 0)
    lines = {n: _label_lines(n) for n in layer}
    widths = {i: max(len(line) for n in members for line in lines[n]) * _CHAR_PX + 16 for i, members in columns.items()}
    left, x = {}, _MARGIN
    for i in sorted(columns):
        left[i] = x
        x += widths[i] + _GAP_PX
    width = x - _GAP_PX + _MARGIN
    box = {n: (left[layer[n]], _MARGIN + row[n] * _ROW_PX, widths[layer[n]]) for n in layer}
    height = _MARGIN + (max(row.values(), default=0) + 1) * _ROW_PX + 36

    def anchor(n: str, side: str) -> tuple[float, float]:
        x, y, w = box[n]
        if side in ("top", "bottom"):
            return x + w / 2, y + (_BOX_H if side == "bottom" else 0)
        return (x + w if side == "right" else x), y + _BOX_H / 2

    parts = []
    for source in flow_nodes:
        for target in sorted(topology.downstream.get(source, ())):
            if (target, source) in heat_edges:  # the localisation's reverse of a heat coupling: drawn once, as stated
                continue
            kind = "heat" if (source, target) in heat_edges else "fluid"
            if (source, target) in back or layer[target] <= layer[source]:
                (x1, y1), (x2, y2) = anchor(source, "bottom"), anchor(target, "bottom")
                dip = max(y1, y2) + _ROW_PX * 0.7
                d = f"M{x1:.0f},{y1:.0f} C{x1:.0f},{dip:.0f} {x2:.0f},{dip:.0f} {x2:.0f},{y2 + 4:.0f}"
            else:
                (x1, y1), (x2, y2) = anchor(source, "right"), anchor(target, "left")
                bend = _GAP_PX / 2
                d = f"M{x1:.0f},{y1:.0f} C{x1 + bend:.0f},{y1:.0f} {x2 - bend:.0f},{y2:.0f} {x2 - 4:.0f},{y2:.0f}"
            parts.append(f'<path class="edge {kind}" d="{d}" marker-end="url(#arrow)"/>')
    for sensor in off_path:
        owner = topology.place(sensor)
        if owner not in box or owner == sensor:
            continue
        if row[sensor] == row[owner] + 1:  # right below: a short vertical line
            (x1, y1), (x2, y2) = anchor(owner, "bottom"), anchor(sensor, "top")
            d = f"M{x1:.0f},{y1:.0f} L{x2:.0f},{y2:.0f}"
        else:  # further down: around the boxes in between, through the gap on the right
            (x1, y1), (x2, y2) = anchor(owner, "right"), anchor(sensor, "right")
            d = f"M{x1:.0f},{y1:.0f} H{x1 + _GAP_PX / 4:.0f} V{y2:.0f} H{x2:.0f}"
        parts.append(f'<path class="edge observes" d="{d}"/>')
    for n in sorted(box):
        x, y, w = box[n]
        classes = ["node", "sensor" if n in sensors else "component"]
        marks = (("suspect", suspects), ("failing", failing), ("matching", matching))
        classes += [mark for mark, members in marks if n in members]
        first = y + _BOX_H / 2 + 4 - (len(lines[n]) - 1) * _LINE_PX / 2
        text = "".join(f'<tspan x="{x + w / 2:.0f}" y="{first + k * _LINE_PX:.0f}">{html.escape(line)}</tspan>'
                       for k, line in enumerate(lines[n]))
        parts.append(
            f'<g class="{" ".join(classes)}" data-node="{html.escape(local_name(n))}"><title>{html.escape(n)}</title>'
            f'<rect x="{x:.0f}" y="{y:.0f}" width="{w:.0f}" height="{_BOX_H}" rx="{12 if n in sensors else 3}"/>'
            f'<text>{text}</text></g>')
    legend = (f'<text class="legend" x="{_MARGIN}" y="{height - 14}">red: suspects (between the last matching and the '
              f'first failing sensor) · red border: failing sensor · green border: matching sensor · rounded: sensor · '
              f'dashed: heat transfer · dotted: observes</text>')
    style = ("text{font:11px DejaVu Sans Mono,monospace;text-anchor:middle;fill:#222}"
             ".legend{text-anchor:start;font-size:10px;fill:#555}"
             ".node rect{fill:#eef2f8;stroke:#6b7a90;stroke-width:1.2}.sensor rect{fill:#fff}"
             ".suspect rect{fill:#f8c9c4;stroke:#b3261e;stroke-width:2.5}.failing rect{stroke:#b3261e;stroke-width:3}"
             ".matching rect{stroke:#2e7d32;stroke-width:3}"
             ".edge{fill:none;stroke:#7d8797;stroke-width:1.4}.heat{stroke:#d9822b;stroke-dasharray:6 3}"
             ".observes{stroke-dasharray:2 3}")
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
            f'viewBox="0 0 {width:.0f} {height:.0f}"><style>{style}</style><defs><marker id="arrow" viewBox="0 0 8 8" '
            f'refX="7" refY="4" markerWidth="7" markerHeight="7" orient="auto"><path d="M0,0 L8,4 L0,8 z" '
            f'fill="#7d8797"/></marker></defs>{"".join(parts)}{legend}</svg>')


# ====================================================================== the page
def _img(data: bytes, media_type: str, alt: str, css_class: str) -> str:
    encoded = base64.b64encode(data).decode("ascii")
    return f'<img class="{css_class}" alt="{html.escape(alt)}" src="data:{media_type};base64,{encoded}">'


def _png(draw: Callable[[Path], Path]) -> bytes:
    """Bytes of the PNG that ``draw(path)`` writes (the :mod:`service.report.plots` functions write files)."""
    with tempfile.TemporaryDirectory(prefix="graphtwin-report-") as folder:
        return Path(draw(Path(folder) / "figure.png")).read_bytes()


def _number(value: float, digits: int = 3) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}g}"


def _table(header: list[str], rows: list[list[str]], css_class: str = "") -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell}</td>" for cell in r) + "</tr>" for r in rows)
    return f'<table class="{css_class}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _sensor_section(run: StoredRun, diagnosis: StoredDiagnosis | None, series: RunSeries | None, series_note: str) -> str:
    from service.report.plots import plot_measured_vs_model

    failing = diagnosis.failing_sensors if diagnosis else set()
    rows = []
    for sensor in sorted(set(run.units)):
        test = run.metrics.get("test", {}).get(sensor, {})
        train = run.metrics.get("train", {}).get(sensor, {})
        verdict = ('<span class="bad">yes</span>' if sensor in failing else "no") if diagnosis else "–"
        rows.append([html.escape(local_name(sensor)), _number(train.get("rmse")), _number(test.get("rmse")),
                     _number(test.get("mae")), _number(test.get("r2")), _number(test.get("cv_rmse_percent")),
                     _number(test.get("nmbe_percent")), html.escape(unit_label(run.units[sensor])), verdict])
    out = ["<h2>Measured against the model, per sensor</h2>",
           _table(["sensor", "train RMSE", "test RMSE", "test MAE", "test R²", "CV(RMSE) %", "NMBE %", "unit",
                   "located failure"], rows, "metrics")]
    if diagnosis:
        out.append("<p>Located failure: the diagnosis located a failure at this sensor (a sensor that only inherits "
                   "a failure from upstream is not located again).</p>")
    if series is None:
        out.append(f'<p class="note">No measured-vs-model figures: {html.escape(series_note)}</p>')
        return "".join(out)
    out.append(f'<p>{series.window.capitalize()} window. The model is simulated at the stored estimates; the band '
               f'is the {100 * INTERVAL_LEVEL:.0f} % prediction interval '
               f'ŷ ± {_Z:.3f}·s with s the sensor\'s training RMSE.</p>')
    out += [f'<p class="note">{html.escape(note)}</p>' for note in series.notes]
    for sensor in series.predicted:
        picture = _png(lambda path, s=sensor: plot_measured_vs_model(
            path, series.timestamps, {s: series.observed[s]}, {"model": {s: series.predicted[s]}}, series.units,
            {s: series.band[s]}, title=f"{local_name(s)}: {series.window} window, RMSE {series.rmse[s]:.3g} "
                                       f"{unit_label(series.units[s])}", interval_level=INTERVAL_LEVEL))
        out.append(f'<figure>{_img(picture, "image/png", f"measured vs model: {local_name(sensor)}", "series")}</figure>')
    return "".join(out)


def _topology_section(store: GraphStore, run: StoredRun, diagnosis: StoredDiagnosis | None) -> str:
    out = ["<h2>Where along the flow path the model fails</h2>"]
    if not store.has_model(run.model):
        return out[0] + f'<p class="note">Model {html.escape(run.model)} is no longer in the store: no topology.</p>'
    topology = FlowTopology.from_store(store, run.model)
    heat = {(r["from"].value, r["to"].value) for r in store.run_named_query("flow-edges", dataset=run.model)
            if r["kind"].value == "heat"}
    svg = topology_svg(topology, set(run.units) | _boundary_nodes(store, run.model),
                       suspects=diagnosis.suspects if diagnosis else set(),
                       failing=diagnosis.failing_sensors if diagnosis else set(),
                       matching=diagnosis.matching_sensors if diagnosis else set(), heat_edges=heat)
    out.append(f'<figure>{_img(svg.encode("utf-8"), "image/svg+xml", f"flow topology of {run.model}", "topology")}</figure>')
    if diagnosis is None:
        out.append('<p class="note">No diagnosis is based on this run: nothing is located.</p>')
    elif not diagnosis.locations:
        out.append("<p>The diagnosis located no failure: the model matches every sensor within its noise.</p>")
    else:
        items = "".join(
            f'<li>{html.escape(loc["text"])} <span class="suspects">Suspects: '
            f'{html.escape(", ".join(local_name(c) for c in loc["components"]) or "none")}</span></li>'
            for loc in diagnosis.locations)
        out.append(f'<ul class="locations">{items}</ul>')
    return "".join(out)


def _boundary_nodes(store: GraphStore, model: str) -> set[str]:
    """Building nodes of the measuring devices the assembly made boundary inputs."""
    return {r["node"].value for r in store.run_named_query("assembled-components", model=model)
            if r["role"].value == "boundary input"}


def _regimes_section(run: StoredRun) -> str:
    out = "<h2>Operating regimes</h2>"
    if not run.regimes:
        return out + '<p class="note">The run has no test window, so no error per regime.</p>'
    sensors = [s for s in run.metrics.get("test", {}) if any(s in r["rmse"] for r in run.regimes)]
    rows = [[html.escape(r["regime"]), html.escape(r["rule"]), f"{100 * r['share']:.0f} %"]
            + [f"{_number(r['rmse'][s])} {html.escape(unit_label(run.units.get(s, '')))}" if s in r["rmse"] else "–"
               for s in sensors] for r in run.regimes]
    header = ["regime", "rule", "share of the test window"] + [f"RMSE {local_name(s)}" for s in sensors]
    return (out + "<p>Clusters of the boundary inputs (mini-batch k-means), each described by the rule of a "
            "shallow decision tree, and the test RMSE of every sensor in each: where the model fails.</p>"
            + _table(header, rows, "regimes"))


def _estimates_section(run: StoredRun) -> str:
    """The run's parameter estimates: median and 16–84 % interval (the point fit's ±1 standard error,
    the posterior's quantiles), unit, and whether the data identified the parameter."""
    rows = [[html.escape(local_name(e["node"])), html.escape(e["name"]), _number(e["median"], 4),
             f"{_number(e['quantile16'], 4)} – {_number(e['quantile84'], 4)}", html.escape(e["unit"]),
             "yes" if e["identified"] else '<span class="bad">no</span>'] for e in run.estimates.values()]
    return ("<h2>Parameter estimates</h2>"
            + _table(["node", "parameter", "estimate", "16–84 %", "unit", "identified"], rows, "estimates"))


def _diagnosis_sections(diagnosis: StoredDiagnosis | None) -> str:
    if diagnosis is None:
        return "<h2>Which effect is missing</h2><p class=\"note\">No diagnosis is based on this run.</p>"
    if not diagnosis.effects:
        return ("<h2>Which effect is missing</h2><p class=\"note\">The effect catalog was not tested on this run "
                "(<code>graphtwin compare</code> locates the failures only; <code>graphtwin diagnose</code> tests the "
                "catalog).</p>")
    effects = _table(
        ["rank", "effect", "at", "significant", "test error removed", "ΔBIC", "score", "p", "evidence"],
        [[str(e["rank"]), f'<span class="effect">{html.escape(e["effect"])}</span><br>'
                          f'<small>{html.escape(e["label"])}</small>',
          html.escape(local_name(e["node"])), '<span class="good">yes</span>' if e["significant"] else "no",
          f"{100 * e['test_improvement']:.0f} %" if np.isfinite(e["test_improvement"]) else "–",
          _number(e["delta_bic"], 4), _number(e["score"]), _number(e["p_value"], 2), html.escape(e["explanation"])]
         for e in diagnosis.effects], "effects")
    return (f"<h2>Which effect is missing (best first)</h2><p>Significant: ΔBIC &lt; −10 and at least 20 % of the "
            f"test-window error removed.</p>{effects}")


def _history_section(store: GraphStore, run: StoredRun) -> str:
    from service.report.plots import plot_error_history

    history = error_history(store, run.model)
    versions, units = history.versions, history.units
    out = ["<h2>Error across model versions</h2>"]
    if not versions:
        return out[0] + '<p class="note">No calibration of this model with a test window is stored.</p>'

    def cells(values: list[float], sensor: str) -> list[str]:
        return [f"{_number(v)} {html.escape(unit_label(units.get(sensor, '')))}" if v == v else "–" for v in values]

    out.append('<p class="note">Each version\'s latest calibration with a test window (this run\'s numbers are in the '
               'tables above where it is that calibration).</p>')
    if not history.comparable:
        out.append('<p class="note bad">The versions were tested on different data or windows: their errors differ by '
                   'that as much as by the model.</p>')
    rows = [[html.escape(local_name(s))] + cells(values, s) for s, values in history.rmse.items()]
    rows.append(["tested on"] + [html.escape(t) for t in history.tested_on])
    out.append(_table(["sensor"] + versions, rows, "history"))
    if history.regime_rmse:
        rows = [[str(number), html.escape(rule), html.escape(local_name(s))] + cells(values, s)
                for number, (rule, sensors) in enumerate(history.regime_rmse.items()) for s, values in sensors.items()]
        out.append(_table(["regime", "rule", "sensor"] + versions, rows, "history-regimes"))
    picture = _png(lambda path: plot_error_history(path, history))
    out.append(f'<figure>{_img(picture, "image/png", f"test RMSE across versions of {run.model}", "history")}</figure>')
    return "".join(out)


_STYLE = """body{font:14px/1.45 system-ui,sans-serif;margin:24px auto;max-width:1240px;color:#1d232b;padding:0 16px}
h1{font-size:22px}h2{font-size:17px;margin-top:30px;border-bottom:1px solid #d5dae1;padding-bottom:4px}
table{border-collapse:collapse;margin:8px 0;font-size:13px}th,td{border:1px solid #d5dae1;padding:3px 7px;
vertical-align:top;text-align:left}th{background:#f1f4f8}.note{color:#8a4b00;background:#fff6e5;padding:6px 10px}
figure{margin:10px 0;overflow-x:auto}img{max-width:100%}.bad{color:#b3261e;font-weight:600}
.good{color:#2e7d32;font-weight:600}.summary{font-weight:600;background:#eef6ee;padding:8px 12px}dl{display:grid;
grid-template-columns:max-content auto;gap:2px 14px}dt{color:#5a6472}dd{margin:0}"""


def _start_text(start_from: dict) -> str:
    """A run's ``start_from`` setting (:func:`service.calibration.run.calibrated_start`) in words."""
    runs = ", ".join(run.rsplit("/", 1)[-1] for run in start_from["runs"])
    return f"the latest calibration of {start_from['model']} (run {runs})"


def report_html(store: GraphStore, run_id: str, *, locate_data: Callable[[str], Path] | None = None) -> str:
    """The report page of run ``run_id`` (a calibration run, or a diagnosis graph ``<run>-diagnosis``).

    :param locate_data: the run's recorded data source (``gt:dataSource``) → the file's path; raises
        KeyError or FileNotFoundError when it is not available. Without it, or when it raises, the
        page shows the stored numbers without the measured-vs-model figures and says why.
    :raises UnknownRunError: no such run in the store.
    """
    run = read_run(store, run_id)
    diagnosis = read_diagnosis(store, run.run_id)
    series, series_note = None, "no data locator was given"
    if locate_data is not None:
        try:
            series = recompute_series(store, run, locate_data(run.data_source))
        except (KeyError, FileNotFoundError, ValueError) as exc:
            series_note = str(exc.args[0]) if isinstance(exc, KeyError) else str(exc)
    windows = [("train", run.train)] + ([("test", run.test)] if run.test else [])
    facts = "".join(f"<dt>{html.escape(k)}</dt><dd>{html.escape(v)}</dd>" for k, v in [
        ("model", f"{run.model} (version {run.version})"), ("method", run.method), ("data", run.data_source),
        *[(f"{name} window", f"{start} – {end}") for name, (start, end) in windows],
        *([("compared only where", " and ".join(run.settings["only_when"]))] if run.settings.get("only_when") else []),
        *([("warm-up before each window", f"{run.settings['warmup_s'] / 3600:g} h")] if "warmup_s" in run.settings else []),
        *([("training window not scored over its first", f"{run.settings['unscored_start_s'] / 3600:g} h")]
          if "unscored_start_s" in run.settings else []),
        *([("started from", _start_text(run.settings["start_from"]))] if "start_from" in run.settings else []),
        ("finished", run.ended), ("run graph", store.run_graph(run.run_id).value),
        ("diagnosis", diagnosis.iri if diagnosis else "none"),
    ])
    summary = f'<p class="summary">{html.escape(diagnosis.summary)}</p>' if diagnosis and diagnosis.summary else ""
    generated = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    title = f"graphtwin report: {run.run_id}"
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<meta http-equiv=\"Content-Security-Policy\" content=\"{CONTENT_SECURITY_POLICY}\">"
        f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style></head><body>"
        f"<h1>{html.escape(title)}</h1><dl class=\"facts\">{facts}</dl>{summary}"
        f"{_sensor_section(run, diagnosis, series, series_note)}{_estimates_section(run)}"
        f"{_topology_section(store, run, diagnosis)}"
        f"{_regimes_section(run)}{_diagnosis_sections(diagnosis)}{_history_section(store, run)}"
        f"<p class=\"note\">Generated {generated} by graphtwin from the store's graphs ({html.escape(str(GTR))}…); "
        "measured-vs-model series are recomputed from the stored estimates and the run's data file.</p>"
        "</body></html>\n"
    )
