"""SPARQL reads that cannot starve the service (issue 30), on the default on-disk store: a query past
the time limit is stopped (503) and the next one answers at once; reads see the writes made before
them; the per-client and global limits answer 429 with ``Retry-After``; ``/health`` answers while
hostile queries hold every read worker."""

import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager

import pytest
from case_study import CASE_STUDY
from fastapi.testclient import TestClient
from service_fixtures import TOKEN

from service.http.app import create_app
from service.http.deps import ReadAdmission
from service.http.errors import ApiError
from service.settings import Settings

AUTH = {"Authorization": f"Bearer {TOKEN}"}
LIMIT_S = 2.0
# every quad of the store four times over: > 10^12 rows to count
CARTESIAN = ("SELECT (COUNT(*) AS ?n) WHERE { GRAPH ?g { ?a ?b ?c } GRAPH ?h { ?d ?e ?f } GRAPH ?i { ?x ?y ?z } "
             "GRAPH ?j { ?k ?l ?m } }")
SMALL = "ASK { GRAPH ?g { ?s ?p ?o } }"


@contextmanager
def _service(tmp_path, **settings) -> Iterator[TestClient]:
    """The service on an on-disk store holding the case study, with these settings."""
    settings = {"query_timeout_s": LIMIT_S, **settings}
    app = create_app(Settings(data_dir=tmp_path / "service", store_dir=tmp_path / "store", token=TOKEN,
                              executor="threads", **settings))
    with TestClient(app) as client:
        assert client.put("/models/case", content=CASE_STUDY.read_bytes(), headers=AUTH).status_code == 201
        yield client


@pytest.fixture
def disk_client(tmp_path):
    with _service(tmp_path, query_workers=2, query_queue=2, max_queries_per_client=4) as client:
        yield client


def _count(client: TestClient, graph: str) -> int:
    response = client.get("/sparql", params={"query": f"SELECT (COUNT(*) AS ?n) WHERE {{ GRAPH <{graph}> {{ ?s ?p ?o }} }}"})
    assert response.status_code == 200, response.text
    return int(response.json()["results"]["bindings"][0]["n"]["value"])


def test_a_query_past_the_limit_is_stopped_and_the_next_answers_at_once(disk_client):
    began = time.monotonic()
    with ThreadPoolExecutor(2) as pool:  # both workers busy with it
        answers = list(pool.map(lambda _: disk_client.get("/sparql", params={"query": CARTESIAN}), range(2)))
    assert time.monotonic() - began < LIMIT_S + 2
    for answer in answers:
        assert answer.status_code == 503 and f"stopped after {LIMIT_S:g} s" in answer.json()["detail"]
    began = time.monotonic()
    assert disk_client.get("/sparql", params={"query": SMALL}).status_code == 200
    named = disk_client.get("/queries/calibrated-parameters", params={"model": "case"})
    assert named.status_code == 200 and time.monotonic() - began < 1.5, "a stopped query left nothing running"


def test_reads_see_the_writes_made_before_them(disk_client):
    model = "https://w3id.org/graphtwin/resource/graph/model/case"
    loaded = _count(disk_client, model)
    assert loaded > 0
    update = (f"INSERT DATA {{ GRAPH <{model}> {{ <https://example.org/extra> "
              "<http://www.w3.org/2000/01/rdf-schema#label> \"extra\" } }")
    assert disk_client.post("/sparql/update", data={"update": update}, headers=AUTH).status_code == 204
    assert _count(disk_client, model) == loaded + 1
    assert disk_client.delete("/models/case", headers=AUTH).status_code == 204
    assert _count(disk_client, model) == 0
    listed = disk_client.get("/queries/calibrated-parameters", params={"model": "case"})
    assert listed.status_code == 404, listed.text  # neither the model nor a run of it is left


@contextmanager
def _busy(client: TestClient, n: int) -> Iterator[list[Future]]:
    """``n`` hostile queries sent, each holding a place until the time limit stops it; their answers."""
    with ThreadPoolExecutor(n) as pool:
        hostile = [pool.submit(client.get, "/sparql", params={"query": CARTESIAN}) for _ in range(n)]
        time.sleep(0.5)  # admitted and running
        yield hostile


def test_one_client_over_its_limit_gets_429_with_retry_after(tmp_path):
    with _service(tmp_path, query_workers=2, query_queue=2, max_queries_per_client=1) as client:
        with _busy(client, 1):
            refused = client.get("/sparql", params={"query": SMALL})
            assert refused.status_code == 429 and refused.headers["retry-after"] == "1"
            assert "at most 1 SPARQL reads of one client" in refused.json()["detail"]
            assert client.get("/queries/flow-edges").status_code == 429  # the named queries too
        assert client.get("/sparql", params={"query": SMALL}).status_code == 200


def test_the_service_over_its_limit_gets_429(tmp_path):
    with _service(tmp_path, query_workers=1, query_queue=1, max_queries_per_client=5) as client, _busy(client, 2):
        refused = client.get("/sparql", params={"query": SMALL})
        assert refused.status_code == 429 and "runs 2 SPARQL reads already" in refused.json()["detail"]


def test_a_token_counts_across_addresses():
    admission = ReadAdmission(total=10, per_client=1)
    with admission.admitted(["address 10.0.0.1", "token abc"]):
        with pytest.raises(ApiError) as refused, admission.admitted(["address 10.0.0.2", "token abc"]):
            pass
        assert refused.value.status == 429
        with admission.admitted(["address 10.0.0.2"]):
            pass
    with admission.admitted(["address 10.0.0.2", "token abc"]):  # the place is free again
        pass


def test_health_answers_while_four_hostile_queries_hold_every_read_worker(tmp_path):
    # liveness, not speed: every /health answer comes while all four queries still run (a long limit,
    # so that a loaded machine cannot stop them first); the speed is the benchmark's
    with _service(tmp_path, query_workers=4, query_queue=0, max_queries_per_client=4, query_timeout_s=8.0) as client:
        with _busy(client, 4) as hostile:
            for _ in range(10):
                assert client.get("/health").status_code == 200
            running = sum(not answer.done() for answer in hostile)
        assert running == 4, "/health waited for a hostile query"
        assert all(answer.result().status_code == 503 for answer in hostile)
        assert client.get("/sparql", params={"query": SMALL}).status_code == 200
