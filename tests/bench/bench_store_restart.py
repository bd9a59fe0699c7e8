"""Opening the on-disk store again after a large model was deleted (issue 30: a restart spent 60 s
recovering before it answered). A model graph of ``--triples`` triples is written as a model load
writes it (one N-Quads load, a transaction), then dropped as ``DELETE /models/NAME`` drops it (one
``DROP GRAPH`` update); the store is closed and opened again in a fresh process, timing each step of
the opening: pyoxigraph's ``Store(path)`` (RocksDB's recovery), the first scan of the named graphs
(:class:`~service.graph.backend.EmbeddedBackend` looks for staging graphs), a first query. Baseline,
measured in the same run: the same opening after the load, before the drop.

    python tests/bench/bench_store_restart.py [--triples 1200000]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyoxigraph as ox

from service.graph.backend import EmbeddedBackend

GRAPH = ox.NamedNode("https://w3id.org/graphtwin/resource/graph/model/big")

_OPEN = """
import json, sys, time
t0 = time.perf_counter()
import pyoxigraph as ox
store = ox.Store(sys.argv[1])
t1 = time.perf_counter()
graphs = list(store.named_graphs())
t2 = time.perf_counter()
bool(store.query("ASK { GRAPH ?g { ?s ?p ?o } }"))
t3 = time.perf_counter()
print(json.dumps({"open_s": t1 - t0, "named_graphs_s": t2 - t1, "first_query_s": t3 - t2, "graphs": len(graphs)}))
"""


def opening(path: Path) -> dict:
    """The steps of opening the store at ``path`` in a fresh process, seconds."""
    out = subprocess.run([sys.executable, "-c", _OPEN, str(path)], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def _ntriples(n: int) -> bytes:
    lines = [f"<https://example.org/big#s{i // 10}> <https://example.org/big#p{i % 10}> \"{i}\" .\n" for i in range(n)]
    return "".join(lines).encode()


def _sizes(path: Path) -> str:
    wal = sum(p.stat().st_size for p in path.glob("*.log"))
    sst = sum(p.stat().st_size for p in path.glob("*.sst"))
    return f"WAL {wal / 1e6:.0f} MB, SST {sst / 1e6:.0f} MB"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--triples", type=int, default=1_200_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="graphtwin-restart-") as folder:
        path = Path(folder) / "store"
        backend = EmbeddedBackend(path)
        began = time.perf_counter()
        backend.replace_graph(GRAPH, _ntriples(args.triples))
        print(f"{args.triples} triples loaded in {time.perf_counter() - began:.1f} s")
        del backend
        print(f"after the load ({_sizes(path)}), opened again: {opening(path)}", flush=True)
        backend = EmbeddedBackend(path)
        began = time.perf_counter()
        backend.update(f"DROP SILENT GRAPH {GRAPH}")
        print(f"dropped in {time.perf_counter() - began:.1f} s")
        del backend
        print(f"after the drop ({_sizes(path)}), opened again: {opening(path)}", flush=True)
        began = time.perf_counter()
        EmbeddedBackend(path)
        print(f"EmbeddedBackend opened in {time.perf_counter() - began:.1f} s")


if __name__ == "__main__":
    main()
