"""SPARQL query throughput and latency of "latest calibrated parameters of every component"
(``queries/calibrated-parameters.rq``, one building per query, a random one each time) on an on-disk
store holding the calibration results of a portfolio of buildings, against the same query on a
store of a few buildings (the baseline, measured in the same run). Both through the pyoxigraph
store directly and through the HTTP service (``GET /queries/calibrated-parameters?model=…``, uvicorn
on a loopback port, one client after another and several at once).

    python tests/bench/bench_sparql_queries.py [--buildings 1000] [--baseline 10] [--runs 2] [--queries 400]

The results are synthetic but in exactly the shape a calibration writes: a
:class:`~service.calibration.record.CalibrationRecord` per run, built from the case study's
assembly (its estimated parameters, its targets), renamed per building and with random values,
turned into triples by :func:`service.calibration.triples.calibration_triples` and written to the
run's named graph. Every building has ``--runs`` runs, one hour apart, so "latest" has to choose.

Goal (issue 5): report queries per second, median and p99 latency at 1,000 calibrated buildings.
"""

from __future__ import annotations

import argparse
import contextlib
import socket
import statistics
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timedelta, timezone
from pathlib import Path

import httpx
import numpy as np
import pyoxigraph as ox
import uvicorn

from service.calibration.metrics import TargetMetrics
from service.calibration.record import CalibrationRecord, ParameterEstimate
from service.calibration.triples import calibration_triples
from service.graph.store import GraphStore
from service.http.app import create_app
from service.model.assembly import assemble
from service.resources import examples_dir
from service.settings import Settings

CASE_STUDY = examples_dir() / "ventilation_case_study" / "model.ttl"
CASE_PREFIX = "https://example.org/ventilation-case-study#"
START = datetime(2026, 1, 12, tzinfo=timezone.utc)


def _template(store: GraphStore):
    """The case study's estimated parameters and targets: (ref, building node) pairs and target nodes."""
    model = assemble(store, "case")
    parameters = [(ref, model.components[ref.component].node) for ref in model.estimated_parameters]
    targets = [(model.components[t].node, model.components[t].signature.id) for t in model.targets]
    return parameters, targets


def _renamed(iri: str, building: str) -> str:
    return iri.replace("/model/case/", f"/model/{building}/").replace(CASE_PREFIX, f"https://example.org/{building}#")


def _record(building: str, run: int, parameters, targets, rng: np.random.Generator) -> CalibrationRecord:
    """A point-calibration record of ``building`` (run ``run``, ending ``run`` hours after START)."""
    estimates = []
    for ref, node in parameters:
        lower, upper = ref.spec.lower, ref.spec.upper
        median = float(rng.uniform(lower, upper))
        spread = 0.05 * (upper - lower)
        estimates.append(ParameterEstimate(
            key=_renamed(ref.key, building), name=ref.name, component=_renamed(ref.component, building),
            node=_renamed(node, building), unit=ref.spec.unit, lower=lower, upper=upper, median=median,
            quantile16=max(lower, median - spread), quantile84=min(upper, median + spread), map=median,
            standard_error=spread, identified=bool(rng.random() > 0.2),
        ))
    metrics = {}
    for window in ("train", "test"):
        metrics[window] = {}
        for node, _ in targets:
            rmse = float(rng.uniform(0.05, 2.0))
            metrics[window][_renamed(node, building)] = TargetMetrics(
                target=_renamed(node, building), unit="1", n=144, n_parameters=len(estimates), mean_observed=10.0,
                rmse=rmse, mae=0.8 * rmse, r2=float(rng.uniform(0.5, 1.0)), cv_rmse_percent=10 * rmse,
                nmbe_percent=float(rng.normal(0, 2)), lag1_autocorrelation=float(rng.uniform(0, 0.9)),
                guideline14_applies=False, guideline14_pass=None, guideline14_note="")
    ended = START + timedelta(hours=run)
    return CalibrationRecord(
        run_id=f"{building}-point-{run:08x}", model_name=building, model_version="0123456789ab", method="point",
        seed=run, data_source=f"{building}.csv", train_window=(START - timedelta(days=1), START),
        test_window=(START, START + timedelta(hours=6)), started=ended - timedelta(minutes=2), finished=ended,
        settings={"n_starts": 2}, estimates=estimates, metrics=metrics)


def portfolio_store(path: Path, n_buildings: int, runs: int, template, seed: int = 0) -> tuple[GraphStore, int]:
    """An on-disk store at ``path`` with ``runs`` calibration runs of each of ``n_buildings``
    buildings, each in its run graph as a calibration writes it (the quads are bulk-loaded, 100
    buildings a transaction, rather than one SPARQL update per run); returns it and its quad count."""
    store = GraphStore.embedded(path)
    rng = np.random.default_rng(seed)
    parameters, targets = template
    for first in range(0, n_buildings, 100):
        quads = []
        for b in range(first, min(first + 100, n_buildings)):
            building = f"building{b:04d}"
            for run in range(runs):
                record = _record(building, run, parameters, targets, rng)
                graph = store.run_graph(record.run_id)
                quads += [ox.Quad(t.subject, t.predicate, t.object, graph) for t in calibration_triples(
                    record, model_graph=store.model_graph(building).value, assembly=store.assembly_graph(building).value)]
        store.backend.store.extend(quads)
    return store, len(store.backend.store)


def _latencies(query_one, buildings: list[str], n: int, rng: np.random.Generator, expected_rows: int,
               budget_s: float = float("inf")) -> list[float]:
    """Latencies (s) of ``n`` queries of random buildings, fewer (at least 3) when ``budget_s`` runs out.
    A query the service answers with an error stops the benchmark (RuntimeError with the answer)."""
    latencies = []
    end = time.perf_counter() + budget_s
    for name in rng.choice(buildings, size=n):
        if len(latencies) >= 3 and time.perf_counter() > end:
            break
        started = time.perf_counter()
        rows = query_one(str(name))
        latencies.append(time.perf_counter() - started)
        assert rows == expected_rows, f"{name}: {rows} rows, expected {expected_rows}"
    return latencies


def _summary(latencies: list[float], wall_s: float | None = None) -> dict[str, float]:
    wall = wall_s if wall_s is not None else sum(latencies)
    return {"n": len(latencies), "qps": len(latencies) / wall, "median_ms": 1000 * statistics.median(latencies),
            "p99_ms": 1000 * float(np.quantile(latencies, 0.99))}


@contextlib.contextmanager
def http_service(store: GraphStore, folder: Path):
    """The HTTP service on ``store`` (uvicorn on a free loopback port, in a thread); yields its URL."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    # a query time limit far above any latency measured here: a slow query is measured, not refused
    app = create_app(Settings(data_dir=folder, executor="threads", max_result_rows=10_000, query_timeout_s=3600,
                              max_queries_per_client=16), store=store)  # every client here has one address
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        if time.monotonic() > deadline:
            raise RuntimeError("uvicorn did not start within 30 s")
        time.sleep(0.05)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(30)


def measure(store: GraphStore, n_buildings: int, n_queries: int, folder: Path, expected_rows: int,
            clients: int, budget_s: float, report) -> dict[str, dict[str, float]]:
    """The figures of each path (direct, HTTP one client, HTTP ``clients`` at once), each measurement
    ``n_queries`` queries or ``budget_s`` seconds, whichever ends first; ``report(path, figures)``
    is called as each is measured."""
    figures = {}

    def keep(path: str, summary: dict[str, float]) -> None:
        figures[path] = summary
        report(path, summary)

    buildings = [f"building{b:04d}" for b in range(n_buildings)]
    rng = np.random.default_rng(1)

    def direct(name: str) -> int:
        return len(store.run_named_query("calibrated-parameters", model=name))

    _latencies(direct, buildings, 1, rng, expected_rows)  # warm the store's caches
    keep("direct", _summary(_latencies(direct, buildings, n_queries, rng, expected_rows, budget_s)))
    with http_service(store, folder) as url:
        local = threading.local()

        def over_http(name: str) -> int:
            if not hasattr(local, "client"):
                local.client = httpx.Client(base_url=url, timeout=3600)
            response = local.client.get("/queries/calibrated-parameters", params={"model": name})
            if response.status_code != 200:
                raise RuntimeError(f"{response.status_code} for {name}: {response.text[:300]}")
            return len(response.json()["results"]["bindings"])

        _latencies(over_http, buildings, 1, rng, expected_rows)
        keep("http, 1 client", _summary(_latencies(over_http, buildings, n_queries, rng, expected_rows, budget_s)))
        per_client = n_queries // clients
        started = time.perf_counter()
        with ThreadPoolExecutor(clients) as pool:
            parts = list(pool.map(lambda i: _latencies(over_http, buildings, per_client, np.random.default_rng(10 + i),
                                                       expected_rows, budget_s), range(clients)))
        keep(f"http, {clients} clients", _summary([x for part in parts for x in part], time.perf_counter() - started))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--buildings", type=int, default=1000)
    parser.add_argument("--baseline", type=int, default=10, help="buildings in the baseline store")
    parser.add_argument("--runs", type=int, default=2, help="calibration runs per building")
    parser.add_argument("--queries", type=int, default=400, help="queries per measurement")
    parser.add_argument("--clients", type=int, default=4, help="concurrent HTTP clients in the last measurement")
    parser.add_argument("--budget", type=float, default=60.0, help="seconds per measurement at most (>= 3 queries)")
    args = parser.parse_args()

    case = GraphStore.embedded(None)
    case.load_model("case", CASE_STUDY)
    template = _template(case)
    expected_rows = len(template[0])
    print(f"calibrated-parameters.rq, one random building per query ({expected_rows} rows each), "
          f"up to {args.queries} queries or {args.budget:g} s per line (n: queries made)", flush=True)
    results = {}
    with tempfile.TemporaryDirectory(prefix="graphtwin-bench-") as folder:
        for n in (args.baseline, args.buildings):
            started = time.perf_counter()
            store, quads = portfolio_store(Path(folder) / f"store-{n}", n, args.runs, template)
            print(f"{n} buildings x {args.runs} runs: {quads} quads loaded in {time.perf_counter() - started:.1f} s")
            print(f"{'path':<18}{'buildings':>10}{'n':>6}{'q/s':>10}{'median ms':>12}{'p99 ms':>10}"
                  f"{'median x':>10}{'p99 x':>8}", flush=True)
            results[n] = measure(store, n, args.queries, Path(folder) / f"service-{n}", expected_rows, args.clients,
                                 args.budget, report=lambda path, r, n=n: _print_line(path, n, r, results, args.baseline))
            del store


def _print_line(path: str, n: int, r: dict, results: dict, baseline: int) -> None:
    """One row of the table; against the baseline's row of the same path when there is one."""
    base = results.get(baseline, {}).get(path)
    ratio = (f"{r['median_ms'] / base['median_ms']:>10.2f}{r['p99_ms'] / base['p99_ms']:>8.2f}"
             if base is not None and n != baseline else f"{'(base)':>10}{'':>8}")
    print(f"{path:<18}{n:>10}{r['n']:>6}{r['qps']:>10.2f}{r['median_ms']:>12.2f}{r['p99_ms']:>10.2f}{ratio}", flush=True)


if __name__ == "__main__":
    main()
