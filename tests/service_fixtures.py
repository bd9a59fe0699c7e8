"""Fixtures for the HTTP service (settings in a temporary folder, an in-memory store with the case
study as model ``case``, a client with the write token, one day of synthetic measurements) and, from
``oxigraph_server.py``, a real Oxigraph server from the PyPI ``oxigraph`` package with an endpoint
backend on it."""

import time

import pytest
from case_study import CASE_STUDY, case_study_data
from fastapi.testclient import TestClient
from oxigraph_server import endpoint_backend, oxigraph_server  # noqa: F401 (pytest fixtures, shared with every test here)

from service.graph.store import GraphStore
from service.http.app import create_app
from service.settings import Settings

TOKEN = "test-token-0123456789"


@pytest.fixture(autouse=True)
def _no_service_environment(monkeypatch):
    """The tests configure the service explicitly; GRAPHTWIN_* variables of the shell must not leak in."""
    import os

    for key in [k for k in os.environ if k.startswith("GRAPHTWIN_")]:
        monkeypatch.delenv(key)


@pytest.fixture(scope="session")
def case_csv(tmp_path_factory):
    """One day of 10-minute synthetic measurements of the case study (columns by gt:timeSeriesId)."""
    path = tmp_path_factory.mktemp("data") / "case.csv"
    case_study_data(path, n_days=1)
    return path


@pytest.fixture
def settings(tmp_path) -> Settings:
    """Jobs run on threads here (the tests swap in work functions that cannot be pickled); the
    process and Dask executors have tests of their own (test_job_executors.py)."""
    return Settings(data_dir=tmp_path / "service", token=TOKEN, query_timeout_s=20, max_result_rows=500,
                    max_upload_bytes=400_000, executor="threads")


@pytest.fixture
def store() -> GraphStore:
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    return store


@pytest.fixture
def auth() -> dict[str, str]:
    return {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def client(settings, store):
    with TestClient(create_app(settings, store=store)) as client:
        yield client


@pytest.fixture
def wait_job():
    """``wait_job(client, id, timeout_s)`` polls until the job has ended and returns it."""

    def wait(client, job_id: str, timeout_s: float = 60.0) -> dict:
        deadline = time.monotonic() + timeout_s
        while True:
            job = client.get(f"/jobs/{job_id}").json()
            if job["status"] not in ("queued", "running"):
                return job
            if time.monotonic() > deadline:
                raise AssertionError(f"job {job_id} still {job['status']} after {timeout_s} s: {job['progress']}")
            time.sleep(0.05)

    return wait


@pytest.fixture
def snapshot():
    """``snapshot(store)``: every quad of an embedded store; equal snapshots mean an unchanged store."""

    def take(store: GraphStore) -> set:
        return set(store.backend.store)

    return take
