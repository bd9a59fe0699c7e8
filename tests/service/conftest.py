"""A real Oxigraph server (the PyPI ``oxigraph`` package's ``oxigraph serve``) on a free loopback port.

``oxigraph_server`` starts one per test module (a fresh store folder), waits until ``/query``
answers, and stops it afterwards; ``endpoint_backend`` hands each test an empty store on it.
Both skip, saying why, when the ``oxigraph`` executable is not installed.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from service.sparql_endpoint_backend import SparqlEndpointBackend

STARTUP_TIMEOUT_S = 15.0


@dataclass(frozen=True)
class OxigraphServer:
    """A running ``oxigraph serve``: its base URL, store folder and process."""

    url: str
    location: Path
    process: subprocess.Popen
    executable: str


def oxigraph_executable() -> str | None:
    """``oxigraph`` on PATH, else beside the running Python (a venv's ``bin/``, not always on PATH)."""
    found = shutil.which("oxigraph")
    if found:
        return found
    beside = Path(sys.executable).parent / "oxigraph"
    return str(beside) if beside.is_file() else None


def _free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _wait_until_answering(url: str, process: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"oxigraph serve exited with {process.returncode}: {log.read_text(errors='replace')}")
        try:
            if httpx.get(f"{url}/query", params={"query": "ASK {}"}, timeout=1.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.05)
    raise RuntimeError(f"oxigraph serve at {url} did not answer within {STARTUP_TIMEOUT_S} s: {log.read_text(errors='replace')}")


@pytest.fixture(scope="module")
def oxigraph_server(tmp_path_factory):
    executable = oxigraph_executable()
    if executable is None:
        pytest.skip("the oxigraph server executable is not installed (pip install oxigraph; it is in the [test] extra)")
    root = tmp_path_factory.mktemp("oxigraph")
    location, log = root / "store", root / "server.log"
    port = _free_loopback_port()
    url = f"http://127.0.0.1:{port}"
    with log.open("wb") as log_file:
        process = subprocess.Popen(
            [executable, "serve", "--location", str(location), "--bind", f"127.0.0.1:{port}"],
            stdout=log_file, stderr=subprocess.STDOUT,
        )
    try:
        _wait_until_answering(url, process, log)
        yield OxigraphServer(url, location, process, executable)
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@pytest.fixture
def endpoint_backend(oxigraph_server):
    """A :class:`SparqlEndpointBackend` on the module's server, emptied before the test."""
    backend = SparqlEndpointBackend.for_oxigraph_server(oxigraph_server.url)
    backend.update("DROP SILENT ALL")
    yield backend
    backend.close()
