"""A real Oxigraph server for the tests, from the PyPI ``oxigraph`` package (the ``test`` extra).

Import the fixtures into a test module (or a conftest) to use them::

    from oxigraph_server import endpoint_backend, oxigraph_server  # noqa: F401 (pytest fixtures)

``oxigraph_server`` (session scope) runs ``oxigraph serve --location DIR --bind 127.0.0.1:PORT`` on a
free loopback port, waits until ``/query`` answers and stops the server at the end of the session; it
skips the tests, saying why, when the ``oxigraph`` executable is not installed. ``endpoint_backend``
is a :class:`~service.graph.endpoint.SparqlEndpointBackend` on it, emptied before each test.
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

__all__ = ["OxigraphServer", "endpoint_backend", "free_loopback_port", "oxigraph_executable", "oxigraph_server"]

STARTUP_LIMIT_S = 30.0
PORT_ATTEMPTS = 3


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 nothing listens on at the time of the call."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def oxigraph_executable() -> str | None:
    """The ``oxigraph`` command next to this Python (a virtual environment's ``bin``), else on PATH."""
    beside = Path(sys.executable).parent / "oxigraph"
    return str(beside) if beside.is_file() else shutil.which("oxigraph")


@dataclass
class OxigraphServer:
    url: str
    location: Path
    process: subprocess.Popen
    log: Path


def _stop(process: subprocess.Popen) -> None:
    process.terminate()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(timeout=10)


def _start(executable: str, location: Path, log: Path) -> OxigraphServer | str:
    """A running server, or why it did not start (its log's end)."""
    port = free_loopback_port()
    url = f"http://127.0.0.1:{port}"
    with log.open("wb") as output:
        process = subprocess.Popen([executable, "serve", "--location", str(location), "--bind", f"127.0.0.1:{port}"],
                                   stdin=subprocess.DEVNULL, stdout=output, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + STARTUP_LIMIT_S
    while process.poll() is None and time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/query", params={"query": "ASK {}"}, timeout=2).status_code == 200:
                return OxigraphServer(url, location, process, log)
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    if process.poll() is None:
        _stop(process)
        return f"no answer on {url}/query within {STARTUP_LIMIT_S:g} s"
    return f"exited with status {process.returncode}: {log.read_text(errors='replace')[-2000:]}"


@pytest.fixture(scope="session")
def oxigraph_server(tmp_path_factory):
    """An ``oxigraph serve`` for the test session (another free port is tried if one was taken meanwhile)."""
    executable = oxigraph_executable()
    if executable is None:
        pytest.skip("the Oxigraph server executable `oxigraph` is not installed (pip install oxigraph, in the test extra)")
    folder = tmp_path_factory.mktemp("oxigraph")
    failures = []
    for attempt in range(PORT_ATTEMPTS):
        started = _start(executable, folder / f"store-{attempt}", folder / f"server-{attempt}.log")
        if isinstance(started, OxigraphServer):
            break
        failures.append(started)
    else:
        pytest.fail("oxigraph serve did not start: " + " | ".join(failures))
    try:
        yield started
    finally:
        _stop(started.process)


@pytest.fixture
def endpoint_backend(oxigraph_server):
    """A :class:`SparqlEndpointBackend` on the session's server, emptied (``DROP SILENT ALL``) first."""
    from service.graph.endpoint import SparqlEndpointBackend

    with SparqlEndpointBackend.for_oxigraph_server(oxigraph_server.url) as backend:
        backend.update("DROP SILENT ALL")
        yield backend
