"""Signature matching at scale: a generated campus of air handling units, each with a return-air
recirculation loop (``tests/bench/campus_graph.py``), loaded into Oxigraph in memory; every
signature of ``signatures/`` (components and effects) matched in one :class:`MatchSession`.

Baseline, measured in the same run: the same queries (the whole query of each signature, as
``graphtwin signature explain`` prints it) on rdflib over the 10k-triple campus. rdflib returns the
reachable combinations without the nearest condition, so it does less work than graphtwin.

    python tests/bench/bench_signature_matching.py [--triples 100000 1000000] [--baseline 10000]

Goal (issue 2): all signatures matched at 1M triples in under 2 s on one core, in memory. Times are
CPU seconds of this process (one core: the store evaluates a query on one thread) and wall seconds;
on a shared machine the CPU figure is the one to compare.
"""

from __future__ import annotations

import argparse
import gc
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyoxigraph as ox
from campus_graph import ahus_for_triples, campus_turtle  # run as a script: tests/bench is on the path

from service.components.library import SignatureLibrary
from service.graph.store import GraphStore
from service.matching.compiler import compile_signature
from service.matching.matcher import MatchSession, match_signature
from service.runtime import cyclic_gc_paused

GOAL_S = 2.0
GOAL_TRIPLES = 1_000_000


class Clock:
    """CPU and wall seconds since creation."""

    def __init__(self):
        self.cpu, self.wall = time.process_time(), time.perf_counter()

    def read(self) -> tuple[float, float]:
        return time.process_time() - self.cpu, time.perf_counter() - self.wall


def load_campus(target_triples: int) -> tuple[GraphStore, int, int, tuple[float, float]]:
    """A store holding a campus of about ``target_triples`` triples: (store, units, triples
    matched over (model + inferred + ontologies), (cpu, wall) seconds to load and align)."""
    n_units = ahus_for_triples(target_triples)
    turtle = campus_turtle(n_units).encode()
    store = GraphStore.embedded(None)
    store.ensure_ontologies()
    clock = Clock()
    store.load_model("campus", turtle, "ttl")
    load = clock.read()
    n_triples = sum(store.backend.triple_count(g) for g in store.matching_dataset("campus"))
    return store, n_units, n_triples, load


def match_all(store: GraphStore, library) -> tuple[dict[str, tuple[int, float, float]], tuple[float, float]]:
    """Match every signature in one session, the cyclic GC paused over the library as ``assemble``
    pauses it: id → (matches, cpu s, wall s), and the totals (the collection after the library
    included; the load's garbage is collected before the clock starts)."""
    gc.collect()
    session = MatchSession(store, store.matching_dataset("campus"))
    per_signature = {}
    total = Clock()
    with cyclic_gc_paused():
        for signature_id, signature in library.items():
            clock = Clock()
            found = match_signature(store, signature, session=session)
            per_signature[signature_id] = (len(found), *clock.read())
    gc.collect()  # what the pause deferred
    return per_signature, total.read()


def rdflib_baseline(store: GraphStore, library, cap_s: float) -> tuple[int, dict[str, tuple[int | None, float]]]:
    """The whole query of every signature on rdflib over the same graphs, each in a child process
    that stops after ``cap_s`` CPU seconds: (triples, id → (rows, or None when stopped; CPU s))."""
    with tempfile.TemporaryDirectory() as folder:
        data = Path(folder) / "campus.nt"
        data.write_bytes(b"".join(store.backend.dump(g, ox.RdfFormat.N_TRIPLES) for g in store.matching_dataset("campus")))
        per_signature = {}
        for signature_id in library:
            command = [sys.executable, __file__, "--rdflib-query", signature_id, str(data), "--rdflib-cap", str(cap_s)]
            n_triples, rows, cpu = subprocess.run(command, capture_output=True, text=True, check=True).stdout.split()
            per_signature[signature_id] = (None if rows == "stopped" else int(rows), float(cpu))
    return int(n_triples), per_signature


def _rdflib_query(signature_id: str, data: Path, cap_s: float) -> None:
    """Child process: print the graph size, the rows (or ``stopped`` after ``cap_s`` CPU seconds) and
    the CPU seconds of one signature's query."""
    import rdflib

    graph = rdflib.Graph()
    graph.parse(data, format="nt")
    text = compile_signature(SignatureLibrary.load()[signature_id]).text

    def stop(*_):
        raise TimeoutError

    signal.signal(signal.SIGPROF, stop)
    clock = Clock()
    signal.setitimer(signal.ITIMER_PROF, cap_s)  # CPU time of this process
    try:
        rows = str(sum(1 for _ in graph.query(text)))
    except TimeoutError:
        rows = "stopped"
    signal.setitimer(signal.ITIMER_PROF, 0)
    print(len(graph), rows, clock.read()[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--triples", type=int, nargs="+", default=[100_000, GOAL_TRIPLES])
    parser.add_argument("--baseline", type=int, default=10_000, help="campus size for rdflib and graphtwin side by side")
    parser.add_argument("--rdflib-cap", type=float, default=10.0, help="CPU seconds after which an rdflib query is stopped")
    parser.add_argument("--rdflib-query", nargs=2, metavar=("SIGNATURE", "NT_FILE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.rdflib_query:
        _rdflib_query(args.rdflib_query[0], Path(args.rdflib_query[1]), args.rdflib_cap)
        return
    library = SignatureLibrary.load()

    store, n_units, n_triples, _ = load_campus(args.baseline)
    baseline_triples, baseline = rdflib_baseline(store, library, args.rdflib_cap)
    baseline_cpu = sum(cpu for _, cpu in baseline.values())
    stopped = [sid for sid, (rows, _) in baseline.items() if rows is None]
    ours, (ours_cpu, _) = match_all(store, library)
    at_least = "at least " if stopped else ""
    print(f"baseline at {baseline_triples} triples ({n_units} units): rdflib, the whole query of every signature: "
          f"{at_least}{baseline_cpu:.1f} s CPU; graphtwin, every signature matched: {ours_cpu:.3f} s CPU "
          f"({at_least}{baseline_cpu / ours_cpu:.0f}x faster)")
    if stopped:
        print(f"  rdflib stopped after {args.rdflib_cap:.0f} s CPU (counted as that): {', '.join(stopped)}")
    finished = sorted(((cpu, sid, rows) for sid, (rows, cpu) in baseline.items() if rows is not None), reverse=True)
    print("  rdflib's slowest finished: " + ", ".join(f"{sid} {cpu:.2f} s ({rows} rows)" for cpu, sid, rows in finished[:3]))

    for target in args.triples:
        store, n_units, n_triples, (load_cpu, load_wall) = load_campus(target)
        results, (total_cpu, total_wall) = match_all(store, library)
        print(f"\ncampus of {n_units} units, {n_triples} triples (model + inferred + ontologies), in memory")
        print(f"  load + alignment: {load_cpu:.1f} s CPU, {load_wall:.1f} s wall")
        print(f"  {'signature':20s} {'matches':>8s} {'CPU s':>7s} {'wall s':>7s}")
        for signature_id, (count, cpu, wall) in results.items():
            print(f"  {signature_id:20s} {count:8d} {cpu:7.3f} {wall:7.3f}")
        print(f"  all {len(results)} signatures: {total_cpu:.2f} s CPU, {total_wall:.2f} s wall; "
              f"{n_triples / total_cpu / 1e6:.2f} M triples per CPU second, "
              f"{at_least}{(n_triples / total_cpu) / (baseline_triples / baseline_cpu):.0f}x rdflib's rate at {baseline_triples}")
        if n_triples >= 0.9 * GOAL_TRIPLES:
            verdict = "met" if total_cpu < GOAL_S else "NOT met"
            print(f"  goal: all signatures at ~1M triples in < {GOAL_S:.0f} s on one core: {verdict} ({total_cpu:.2f} s CPU)")


if __name__ == "__main__":
    main()
