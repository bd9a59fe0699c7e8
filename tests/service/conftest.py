"""Fixtures for the HTTP service (settings in a temporary folder, an in-memory store with the case
study as model ``case``, a client with the write token, one day of synthetic measurements) and for
the SPARQL endpoint backend (a real Oxigraph server from the PyPI ``oxigraph`` package)."""

import shutil
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import httpx

import pytest
from case_study import CASE_STUDY
from fastapi.testclient import TestClient

from service.api import create_app
from service.resources import signatures_dir
from service.settings import Settings
from service.signature import load_signature_library
from service.store import GraphStore
from service.synthetic_data import generate_synthetic_data

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
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    path = tmp_path_factory.mktemp("data") / "case.csv"
    generate_synthetic_data(store, "case", path, library=load_signature_library(signatures_dir()), n_days=1)
    return path


@pytest.fixture
def settings(tmp_path) -> Settings:
    return Settings(data_dir=tmp_path / "service", token=TOKEN, query_timeout_s=20, max_result_rows=500,
                    max_upload_bytes=400_000)


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


# ---------------------------------------------------------------------- a real Oxigraph server
def _free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on (at the time of the call)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@dataclass
class OxigraphServer:
    url: str
    location: Path
    process: subprocess.Popen


@pytest.fixture(scope="session")
def oxigraph_server(tmp_path_factory):
    """``oxigraph serve --location DIR --bind 127.0.0.1:PORT`` for the session; stopped at the end."""
    executable = shutil.which("oxigraph") or shutil.which("oxigraph", path=str(Path(sys.executable).parent))
    if executable is None:
        pytest.skip("the oxigraph server executable is not installed (pip install oxigraph)")
    location = tmp_path_factory.mktemp("oxigraph")
    port = _free_loopback_port()
    process = subprocess.Popen([executable, "serve", "--location", str(location), "--bind", f"127.0.0.1:{port}"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    server = OxigraphServer(f"http://127.0.0.1:{port}", location, process)
    deadline = time.monotonic() + 30
    try:
        while True:
            if process.poll() is not None:
                pytest.fail(f"oxigraph serve exited with {process.returncode}: {process.stderr.read().decode()[-2000:]}")
            try:
                if httpx.get(f"{server.url}/query", params={"query": "ASK {}"}, timeout=2).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"oxigraph serve did not answer on {server.url} within 30 s")
            time.sleep(0.1)
        yield server
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)
        process.stderr.close()


@pytest.fixture
def endpoint_backend(oxigraph_server):
    """A :class:`SparqlEndpointBackend` on the session's server, emptied before each test."""
    from service.sparql_endpoint_backend import SparqlEndpointBackend

    with SparqlEndpointBackend.for_oxigraph_server(oxigraph_server.url) as backend:
        backend.update("DROP SILENT ALL")
        yield backend
