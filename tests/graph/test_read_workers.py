"""Read queries on worker processes (:mod:`service.graph.read_workers`): a query past its time limit is
stopped and its worker replaced; reads see every write made before them (checkpoints made after a
write, old ones removed)."""

import json
import subprocess
import sys
import time

import pyoxigraph as ox
import pytest

from service.errors import QueryTimeoutError, ResultTooLargeError
from service.graph.backend import EmbeddedBackend
from service.graph.query_answers import SparqlQuery
from service.graph.read_workers import ReadWorkers

G = ox.NamedNode("https://example.org/g")
CARTESIAN = ("SELECT (COUNT(*) AS ?n) WHERE { GRAPH ?g1 { ?a ?b ?c } GRAPH ?g2 { ?d ?e ?f } GRAPH ?g3 { ?h ?i ?j } "
             "GRAPH ?g4 { ?k ?l ?m } GRAPH ?g5 { ?n1 ?o ?p } }")
COUNT = "SELECT (COUNT(*) AS ?n) WHERE { GRAPH ?g { ?s ?p ?o } }"


def _select(text: str) -> SparqlQuery:
    return SparqlQuery(text, "SELECT", "application/sparql-results+json")


def _count(workers: ReadWorkers, timeout_s: float = 30) -> int:
    answer = json.loads(workers.answer(_select(COUNT), max_rows=10, timeout_s=timeout_s))
    return int(answer["results"]["bindings"][0]["n"]["value"])


def _triples(n: int, object_offset: int = 0) -> list[ox.Triple]:
    return [ox.Triple(ox.NamedNode(f"https://example.org/s{i}"), ox.NamedNode("https://example.org/p"),
                      ox.Literal(i + object_offset)) for i in range(n)]


@pytest.fixture
def disk(tmp_path):
    backend = EmbeddedBackend(tmp_path / "store")
    workers = ReadWorkers(backend, 1, tmp_path / "snapshots")
    yield backend, workers
    workers.close()


def test_reads_see_every_write_made_before_them_and_old_checkpoints_go(disk, tmp_path):
    backend, workers = disk
    assert _count(workers) == 0
    backend.replace_graph(G, _triples(5))
    assert _count(workers) == 5
    backend.update(f"INSERT DATA {{ GRAPH {G} {{ <https://example.org/x> <https://example.org/p> 1 }} }}")
    assert _count(workers) == 6
    backend.drop_graph(G)
    assert _count(workers) == 0
    assert len(list((tmp_path / "snapshots").iterdir())) == 1, "the worker let go of the older checkpoints"


def test_reads_without_a_write_between_share_one_checkpoint(disk, tmp_path):
    backend, workers = disk
    backend.replace_graph(G, _triples(3))
    before = backend.generation
    assert [_count(workers) for _ in range(3)] == [3, 3, 3]
    assert backend.generation == before and [p.name for p in (tmp_path / "snapshots").iterdir()] == ["checkpoint-1"]


def test_a_query_past_the_limit_is_stopped_and_its_worker_replaced(disk):
    backend, workers = disk
    backend.replace_graph(G, _triples(300))
    first = workers.pids
    began = time.monotonic()
    with pytest.raises(QueryTimeoutError, match="stopped after 1 s"):
        workers.answer(_select(CARTESIAN), max_rows=10, timeout_s=1)
    assert time.monotonic() - began < 3
    assert len(workers.pids) == 1 and workers.pids.isdisjoint(first), "a fresh worker took the killed one's place"
    began = time.monotonic()
    assert _count(workers) == 300 and time.monotonic() - began < 5  # nothing left running in the way


def test_errors_of_the_query_reach_the_caller_and_the_worker_stays(disk):
    backend, workers = disk
    backend.replace_graph(G, _triples(20))
    pids = workers.pids
    with pytest.raises(SyntaxError):
        workers.answer(_select("SELECT * WHERE { ?s"), max_rows=10, timeout_s=30)
    with pytest.raises(ResultTooLargeError, match="more than 10 rows"):
        workers.answer(_select("SELECT * WHERE { GRAPH ?g { ?s ?p ?o } }"), max_rows=10, timeout_s=30)
    assert workers.pids == pids


def test_every_write_moves_the_generation(tmp_path):
    backend = EmbeddedBackend(tmp_path / "store")
    generations = [backend.generation]
    backend.replace_graph(G, _triples(2))
    generations.append(backend.generation)
    backend.replace_graph(G, _triples(2, object_offset=1))
    generations.append(backend.generation)
    backend.drop_graph(G)
    generations.append(backend.generation)
    assert generations == sorted(set(generations))


def _table_files(folder) -> set[str]:
    return {p.name for p in folder.glob("*.sst")}


def test_a_large_write_is_flushed_so_that_opening_the_store_replays_little(tmp_path):
    backend = EmbeddedBackend(tmp_path / "store")
    backend.flush_after_wal_bytes = 1 << 20
    before = _table_files(tmp_path / "store")
    backend.replace_graph(G, _triples(20_000))  # ~12 MB of write-ahead log
    written = _table_files(tmp_path / "store") - before
    assert sum((tmp_path / "store" / name).stat().st_size for name in written) > 1 << 20, \
        "the memtable went to table files: a restart need not replay the log"
    small = EmbeddedBackend(tmp_path / "small")  # a store of its own: no compaction of the flush above under way
    small.flush_after_wal_bytes = 1 << 20
    before = _table_files(tmp_path / "small")
    small.replace_graph(G, _triples(10))
    assert _table_files(tmp_path / "small") == before, "a small write is not flushed"


def test_a_worker_imports_neither_numpy_nor_the_http_stack():
    """Workers start warm and light: a replacement is ready within a fraction of a second."""
    probe = ("import sys, service.graph.read_workers; "
             "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'scipy', 'sklearn', 'fastapi', 'httpx'}))")
    assert subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.strip() == "[]"
