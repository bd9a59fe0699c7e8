"""Faults: a real ``graphtwin serve`` (uvicorn, on-disk store, the default process-pool executor) is
killed with SIGKILL, its job processes with it, while a calibration runs, and started again on the same
folders: the finished results are intact, the interrupted job is marked and can be resubmitted, and
the store holds exactly what it held before the kill (the half-done job wrote nothing)."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from case_study import CASE_STUDY, case_study_data
from oxigraph_server import free_loopback_port

TOKEN = "fault-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
SHORT_TRAIN = "2026-01-12T06:00/2026-01-12T09:00"  # a calibration of about a second
GRAPH_SIZES = "SELECT ?g (COUNT(*) AS ?n) WHERE { GRAPH ?g { ?s ?p ?o } } GROUP BY ?g"


class Server:
    """``graphtwin serve`` in a process group of its own (the pool processes it spawns join it)."""

    def __init__(self, folder: Path):
        self.port = free_loopback_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = {**os.environ, "GRAPHTWIN_TOKEN": TOKEN, "GRAPHTWIN_EXECUTOR": "processes",
               "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        self.log = (folder / f"serve-{self.port}.log").open("wb")
        self.process = subprocess.Popen(
            [sys.executable, "-c", "from service.cli import app; app()", "serve", "--store", str(folder / "store"),
             "--data-dir", str(folder / "service"), "--port", str(self.port)],
            env=env, stdin=subprocess.DEVNULL, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self.client = httpx.Client(base_url=self.url, timeout=30)
        deadline = time.monotonic() + 60
        while True:
            assert self.process.poll() is None, f"graphtwin serve exited: {Path(self.log.name).read_text()[-2000:]}"
            try:
                if self.client.get("/health").status_code == 200:
                    return
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, "graphtwin serve did not answer within 60 s"
            time.sleep(0.1)

    def kill(self, sig: int) -> None:
        """``sig`` to the whole process group; waits for the server to exit."""
        self.client.close()
        try:
            os.killpg(self.process.pid, sig)
        except ProcessLookupError:
            pass
        self.process.wait(timeout=30)
        self.log.close()

    def wait_job(self, job_id: str, timeout_s: float = 120) -> dict:
        deadline = time.monotonic() + timeout_s
        while (job := self.client.get(f"/jobs/{job_id}").json())["status"] in ("queued", "running"):
            assert time.monotonic() < deadline, f"job {job_id} still {job['status']}: {job['progress']}"
            time.sleep(0.05)
        return job

    def upload_four_days(self, folder: Path) -> str:
        """Four days of synthetic case-study data uploaded (a calibration of several seconds: still
        running 0.5 s in on any machine); the upload's id."""
        days = folder / "four_days.csv"
        case_study_data(days, n_days=4)
        return self.client.post("/models/case/measurements", content=days.read_bytes(),
                                headers={**AUTH, "Content-Type": "text/csv"}).json()["id"]

    def wait_in_pool(self, job_id: str) -> None:
        """Until the job's work was sent to the process pool."""
        deadline = time.monotonic() + 30
        while not any(p["message"].startswith("sent to a local process pool")
                      for p in self.client.get(f"/jobs/{job_id}").json()["progress"]):
            assert time.monotonic() < deadline, "the job did not reach the process pool"
            time.sleep(0.02)

    def graph_sizes(self) -> dict[str, int]:
        rows = self.client.get("/sparql", params={"query": GRAPH_SIZES}).json()["results"]["bindings"]
        return {r["g"]["value"]: int(r["n"]["value"]) for r in rows}

    def calibrated_parameters(self) -> list[dict]:
        return self.client.get("/queries/calibrated-parameters", params={"model": "case"}).json()["results"]["bindings"]


@pytest.fixture
def servers(tmp_path):
    started = []

    def start() -> Server:
        started.append(Server(tmp_path))
        return started[-1]

    yield start
    for server in started:
        if server.process.poll() is None:
            server.kill(signal.SIGTERM)
        try:  # pool processes a killed server left behind
            os.killpg(server.process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.mark.slow  # two server starts (each spawning its pool process), three calibrations: ~30 s
def test_a_server_killed_mid_job_restarts_with_finished_results_intact_and_the_job_interrupted(
        servers, case_csv, tmp_path):
    first = servers()
    assert first.client.put("/models/case", content=CASE_STUDY.read_bytes(), headers=AUTH).status_code == 201
    upload = first.client.post("/models/case/measurements", content=case_csv.read_bytes(),
                               headers={**AUTH, "Content-Type": "text/csv"}).json()["id"]
    long_upload = first.upload_four_days(tmp_path)  # the job to kill
    finished = first.wait_job(first.client.post("/jobs/calibrate", headers=AUTH, json={
        "model": "case", "measurements": upload, "train": SHORT_TRAIN}).json()["id"])
    assert finished["status"] == "succeeded", finished
    sizes, parameters = first.graph_sizes(), first.calibrated_parameters()
    assert len(parameters) == len(finished["result"]["parameters"]) > 0

    killed = first.client.post("/jobs/calibrate", headers=AUTH, json={
        "model": "case", "measurements": long_upload, "seed": 1}).json()
    first.wait_in_pool(killed["id"])
    time.sleep(0.5)  # the work is under way in its pool process
    assert first.client.get(f"/jobs/{killed['id']}").json()["status"] == "running"
    first.kill(signal.SIGKILL)

    second = servers()
    assert second.client.get("/health").json()["jobs_active"] == 0
    again = second.client.get(f"/jobs/{finished['id']}").json()
    assert again["status"] == "succeeded" and again["result"] == finished["result"] and again["links"] == finished["links"]
    interrupted = second.client.get(f"/jobs/{killed['id']}").json()
    assert interrupted["status"] == "interrupted" and "while the job was running" in interrupted["error"]
    assert second.graph_sizes() == sizes, "the killed job wrote nothing, the store lost nothing"
    assert second.calibrated_parameters() == parameters

    resubmitted = second.client.post(f"/jobs/{killed['id']}/resubmit", headers=AUTH)
    assert resubmitted.status_code == 202 and resubmitted.json()["resubmitted_from"] == killed["id"]
    redone = second.wait_job(resubmitted.json()["id"])
    assert redone["status"] == "succeeded", redone
    assert {p["run"]["value"].rsplit("/", 1)[-1] for p in second.calibrated_parameters()} == {redone["result"]["run_id"]}
    assert set(second.graph_sizes()) == set(sizes) | {redone["links"]["run_graph"]}


@pytest.mark.slow  # one server start, one calibration of four days started and stopped: ~15 s
def test_sigterm_with_a_job_running_marks_it_interrupted_and_the_server_exits_within_seconds(servers, tmp_path):
    """Before, the server stopped serving on SIGTERM but waited for the running job to end (it had to
    be killed); now the job is marked interrupted, its pool process ended, and the server exits."""
    from service.jobs.records import JobRecords

    server = servers()
    assert server.client.put("/models/case", content=CASE_STUDY.read_bytes(), headers=AUTH).status_code == 201
    job = server.client.post("/jobs/calibrate", headers=AUTH, json={
        "model": "case", "measurements": server.upload_four_days(tmp_path), "seed": 1}).json()
    server.wait_in_pool(job["id"])
    os.kill(server.process.pid, signal.SIGTERM)  # the server alone, as a process manager stops it
    began = time.monotonic()
    server.process.wait(timeout=20)
    assert time.monotonic() - began < 10, "the server waited for its job"
    record = JobRecords(tmp_path / "service" / "jobs").load(job["id"])
    assert record.status == "interrupted" and "while the job ran" in record.error
