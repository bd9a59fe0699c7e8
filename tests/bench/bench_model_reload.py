"""Loading a model again into the on-disk store, as every CLI command does with its model file: the
generated campus of ``tests/bench/campus_graph.py`` loaded with :meth:`GraphStore.load_model` into a
fresh on-disk store, then loaded again unchanged, with one triple added (a model edited), back as it
was, and replaced by another campus of the same size (every unit renamed: the whole graph rewritten).
Baseline, measured in the same run: the first load (parse, alignment, one N-Quads load).

    python tests/bench/bench_model_reload.py [--triples 300000] [--memory]

No goal is set by an issue; what to expect on a 2-core machine (2026-11-27): at 300k triples a first
load of ~10 s, a reload unchanged ~3 s and with one triple added ~7 s (one update of the difference),
another campus of the same size ~40 s (alignment, the held graphs read to find the difference too
large, one ``INSERT DATA`` update). Wall seconds.
"""

from __future__ import annotations

import argparse
import tempfile
import time

from campus_graph import ahus_for_triples, campus_turtle  # run as a script: tests/bench is on the path

from service.graph.store import GraphStore


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--triples", type=int, default=300_000)
    parser.add_argument("--memory", action="store_true", help="the in-memory store instead")
    args = parser.parse_args()
    campus = campus_turtle(ahus_for_triples(args.triples)).encode()
    steps = [
        ("first load (baseline)", campus),
        ("loaded again unchanged", campus),
        ("one triple added", campus + b"\n<urn:bench:edit> <urn:bench:p> \"edited\" .\n"),
        ("back as it was", campus),
        ("another campus, same size", campus.replace(b"ahu", b"unit")),
    ]
    with tempfile.TemporaryDirectory() as folder:
        store = GraphStore.embedded(None if args.memory else folder)
        store.ensure_ontologies()
        baseline = None
        print(f"{'in memory' if args.memory else 'on disk'}, campus of {args.triples} triples requested")
        for label, document in steps:
            start = time.perf_counter()
            triples = store.load_model("campus", document, "ttl").triples
            seconds = time.perf_counter() - start
            baseline = baseline or seconds
            print(f"  {label:28s} {triples:8d} triples {seconds:6.1f} s  {seconds / baseline:5.2f}x the first load")


if __name__ == "__main__":
    main()
