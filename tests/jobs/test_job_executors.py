"""Where job work runs: shipped to a local process pool (the service's default) or to a Dask
distributed cluster (a ``LocalCluster`` on loopback TCP, reached as ``GRAPHTWIN_EXECUTOR=dask://127.0.0.1:PORT``
like a real scheduler), with the results written to the service's store on return. (The fault test,
test_service_faults.py, runs the process pool inside a real ``graphtwin serve``.)"""

import os
import pickle
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pyoxigraph as ox
import pytest
from case_study import CASE_STUDY, EX
from fastapi.testclient import TestClient

from service.errors import (
    ConflictError,
    IncompleteModelError,
    MeasurementError,
    ModelLoadError,
    NotFoundError,
    UnknownEffectError,
)
from service.graph.store import GraphStore
from service.http.app import create_app
from service.jobs.executors import WORK_FOLDER_PREFIX, DaskJobExecutor, ProcessJobExecutor
from service.jobs.kinds import JOB_KINDS, add_effect_job, assemble_job, calibrate_job
from service.jobs.records import JobRecords
from service.jobs.runner import JobRunner
from service.jobs.shipping import ShippedJob, run_shipped_job, ship_job
from service.jobs.work import JobKind, JobResult
from service.model.assembly import assemble
from service.settings import Settings
from service.workflows.requests import (
    AddEffectRequest,
    AssembleRequest,
    CalibrateRequest,
    JobRequest,
)


def _wait(runner: JobRunner, job_id: str, timeout_s: float = 120):
    deadline = time.monotonic() + timeout_s
    while (record := runner.get(job_id)).status in ("queued", "running"):
        assert time.monotonic() < deadline, f"job still {record.status}: {record.progress}"
        time.sleep(0.02)
    return record


def test_a_process_pool_job_failing_on_bad_input_fails_clearly_and_the_pool_runs_the_next_job(case_store, tmp_path):
    """Failures come back as failed jobs naming the problem, also a MeasurementError (which does
    not unpickle as it is); the pool is not broken by them."""
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("time,mystery_sensor\n2026-01-12T00:00,1.0\n2026-01-12T00:10,2.0\n")
    runner = JobRunner(case_store, JobRecords(tmp_path / "jobs"), JOB_KINDS, executor=ProcessJobExecutor(1),
                       locate_measurements={"0123456789abcdef": bad_csv}.__getitem__)
    try:
        failed = _wait(runner, runner.submit("add-effect", AddEffectRequest(
            model="case", effect="FanMotorHeat", target=EX + "heating_valve")).id)
        assert failed.status == "failed" and "does not apply" in failed.error, failed.error
        refused = _wait(runner, runner.submit("calibrate", CalibrateRequest(model="case", measurements="0123456789abcdef")).id)
        assert refused.status == "failed" and f"no column for {EX}supply_air_flow_meter" in refused.error, refused.error
        assert not any(job.error.startswith("internal error") for job in (failed, refused))
        done = _wait(runner, runner.submit("assemble", AssembleRequest(model="case")).id)
        assert done.status == "succeeded", done.error
        assert [p["message"] for p in done.progress][1:3] == ["sent to a local process pool (1 process)",
                                                                "matching the signature library"]
        assert case_store.assembly_graph("case") in case_store.backend.graphs()
        assert "case+FanMotorHeat" not in case_store.models()
    finally:
        runner.shutdown(wait=True)


def test_an_error_travels_from_a_worker_as_it_was_raised():
    """Every class of the error hierarchy unpickles with its type, message and fields (an error whose
    constructor takes more than its message, ``IncompleteModelError(message)``, had listed the
    message's characters one a line in a failed job's error over HTTP)."""
    from service import errors

    made = {IncompleteModelError: IncompleteModelError(["a valve missing", "a fan missing"], headline="incomplete"),
            MeasurementError: MeasurementError("data.csv", ["line 3: not a number"]),
            ModelLoadError: ModelLoadError("m.ttl", "bad IRI", 4, 7),
            UnknownEffectError: UnknownEffectError("Leak", ["ValveLeakage", "ValveStuck"])}
    for name in errors.__all__:
        cls = getattr(errors, name)
        error = made.get(cls) or cls(f"{name}: what went wrong")
        copy = pickle.loads(pickle.dumps(error))
        assert (type(copy), str(copy), copy.__dict__) == (type(error), str(error), error.__dict__), name


def test_a_pool_job_on_an_incomplete_model_fails_with_one_line_a_problem(tmp_path):
    text = CASE_STUDY.read_text(encoding="utf-8").replace(
        "    fso:suppliesFluidTo ex:check_valve .", "    fso:suppliesFluidTo ex:return_water_pipe .")
    store = GraphStore.embedded(None)
    store.load_model("no-check-valve", text.encode())
    runner = JobRunner(store, JobRecords(tmp_path / "jobs"), JOB_KINDS, executor=ProcessJobExecutor(1))
    try:
        failed = _wait(runner, runner.submit("assemble", AssembleRequest(model="no-check-valve")).id)
    finally:
        runner.shutdown(wait=True)
    assert failed.status == "failed" and failed.error.startswith("the model is incomplete:\n  - "), failed.error
    assert f"no Valve downstream of {EX}heating_coil_water_side" in failed.error, failed.error


def test_after_a_pool_worker_dies_the_next_job_runs_in_a_new_pool(case_store, tmp_path):
    """A worker killed (the OOM killer) breaks a process pool for good; the executor starts a new
    one for the next job instead of failing every job until the service restarts."""
    import os
    import signal

    executor = ProcessJobExecutor(1)
    runner = JobRunner(case_store, JobRecords(tmp_path / "jobs"), JOB_KINDS, executor=executor)
    try:
        assert _wait(runner, runner.submit("assemble", AssembleRequest(model="case")).id).status == "succeeded"
        for pid in list(executor._slots[0]._processes):
            os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + 30
        while not executor._slots[0]._broken and time.monotonic() < deadline:
            time.sleep(0.05)
        done = [_wait(runner, runner.submit("assemble", AssembleRequest(model="case")).id) for _ in range(2)]
        assert [job.status for job in done] == ["succeeded", "succeeded"], [job.error for job in done]
    finally:
        runner.shutdown(wait=True)


def _sleep(seconds: float) -> float:
    time.sleep(seconds)
    return seconds


def test_shutting_the_pool_down_stops_a_worker_still_running_a_job():
    """A service stopped while a job runs leaves no orphaned worker computing on. The worker is in a
    process group of its own: a stop sent to the service's group (Ctrl-C) reaches the service, which
    marks the job interrupted, and not the worker first (the job had been recorded as failed)."""
    executor = ProcessJobExecutor(1)
    worker_group = executor.submit(os.getpgrp).result(timeout=60)
    assert worker_group != os.getpgrp() and worker_group in [w.pid for w in executor._slots[0]._processes.values()]
    future = executor.submit(_sleep, 120.0)
    deadline = time.monotonic() + 60
    while not future.running() and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = list(executor._slots[0]._processes.values())
    assert future.running() and [w.is_alive() for w in workers] == [True]
    executor.shutdown()
    assert [w.is_alive() for w in workers] == [False]


def test_a_jobs_scratch_lies_in_the_services_work_folder_and_a_killed_services_folder_goes_at_the_next_start():
    """Each suite run left a job's scratch folder and a progress folder in /tmp: a service killed
    (SIGKILL, out of memory) never reaches its shutdown. A job's scratch now lies in its service's
    work folder, named with the service's process id, and the next service removes the folders of
    processes no longer running; never one of a running process."""
    dead = subprocess.Popen(["true"])
    dead.wait()
    left_by_dead = Path(tempfile.mkdtemp(prefix=f"{WORK_FOLDER_PREFIX}{dead.pid}-"))
    (left_by_dead / "graphtwin-job-x").mkdir()
    of_running = Path(tempfile.mkdtemp(prefix=f"{WORK_FOLDER_PREFIX}{os.getppid()}-"))
    executor = ProcessJobExecutor(1)
    try:
        assert not left_by_dead.exists() and of_running.is_dir()
        progress = executor.progress_path("j1")
        shipped = ShippedJob("j1", JobRequest(), b"", {"u1": b"time,x\n"}, str(progress))
        outcome, *_ = run_shipped_job(lambda store, request, context: JobResult(
            {"folder": str(context.measurements("u1").parent)}), shipped)
        scratch = Path(outcome.result["folder"])
        assert scratch.parent == progress.parent and scratch.name.startswith("graphtwin-job-")
        assert not scratch.exists()  # removed when the job ended
    finally:
        executor.shutdown()
        shutil.rmtree(of_running)
    assert not progress.parent.exists()


class Sleep(JobRequest):
    seconds: float


def _sleep_job(store, request: Sleep, context):
    time.sleep(request.seconds)
    return JobResult({"slept": request.seconds})


def _chatty_job(store, request: Sleep, context):
    context.report("reading the data")
    time.sleep(request.seconds)
    context.report("fitting")
    return JobResult({"slept": request.seconds})


def test_a_pool_job_reports_its_progress_while_it_runs_each_message_once(tmp_path):
    """Shipped work's progress reached the job record only with its result; now it is read from the
    worker's progress file as it comes (HTTP's GET /jobs/{id} shows the phase a long job is in)."""
    runner = JobRunner(GraphStore.embedded(None), JobRecords(tmp_path / "jobs"), {"chatty": JobKind(Sleep, _chatty_job)},
                       executor=ProcessJobExecutor(1))
    try:
        job = runner.submit("chatty", Sleep(seconds=6)).id
        deadline = time.monotonic() + 60
        while "reading the data" not in [p["message"] for p in runner.get(job).progress]:
            assert runner.get(job).status in ("queued", "running"), runner.get(job)
            assert time.monotonic() < deadline, runner.get(job).progress
            time.sleep(0.05)
        assert runner.get(job).status == "running"
        assert JobRecords(tmp_path / "jobs").load(job).progress[-1]["message"] == "reading the data"  # saved too
        messages = [p["message"] for p in _wait(runner, job).progress]
        assert messages.count("reading the data") == 1 and messages.count("fitting") == 1
        assert messages.index("reading the data") < messages.index("fitting")
    finally:
        runner.shutdown(wait=True)


def _workers(executor: ProcessJobExecutor) -> list:
    return [w for pool in executor._slots for w in (pool._processes or {}).values()]


def test_cancelling_a_running_pool_job_stops_its_process_and_leaves_the_other_job_running(tmp_path):
    """A cancelled job's process is terminated (it does not compute on for nothing); the job running
    beside it in the other process finishes, and the next job runs in the new process."""
    executor = ProcessJobExecutor(2)
    runner = JobRunner(GraphStore.embedded(None), JobRecords(tmp_path / "jobs"), {"sleep": JobKind(Sleep, _sleep_job)},
                       max_workers=2, executor=executor)
    try:
        doomed = runner.submit("sleep", Sleep(seconds=120)).id
        other = runner.submit("sleep", Sleep(seconds=4)).id
        deadline = time.monotonic() + 60
        while len([w for w in _workers(executor) if w.is_alive()]) < 2 or any(
                runner.get(j).status != "running" for j in (doomed, other)):
            assert time.monotonic() < deadline, "the two jobs never ran side by side"
            time.sleep(0.05)
        time.sleep(1.0)  # both are in their sleep
        before = {w.pid: w for w in _workers(executor)}
        runner.cancel(doomed)
        assert _wait(runner, doomed).status == "cancelled"
        stopped = [w for w in before.values() if w.exitcode is not None]
        assert len(stopped) == 1 and stopped[0].exitcode < 0, [(w.pid, w.exitcode) for w in before.values()]
        finished = _wait(runner, other)
        assert finished.status == "succeeded" and finished.result == {"slept": 4}
        assert _wait(runner, runner.submit("sleep", Sleep(seconds=0)).id).status == "succeeded"
    finally:
        runner.shutdown(wait=True)


distributed = pytest.importorskip("distributed", reason="the Dask executor needs distributed (the test extra has it)")

SHORT_TRAIN = "2026-01-12T06:00/2026-01-12T09:00"  # 3 h of the synthetic day: a calibration of a few seconds


@pytest.fixture(scope="module")
def dask_cluster():
    """One in-process worker with two threads behind a scheduler on a loopback TCP port."""
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        yield cluster


def test_a_portfolio_is_calibrated_on_the_dask_cluster_and_its_results_are_queryable(dask_cluster, tmp_path, case_csv,
                                                                                   wait_job):
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    store.load_model("school", CASE_STUDY)
    port = dask_cluster.scheduler.port
    settings = Settings(data_dir=tmp_path / "service", token="test-token-0123456789",
                        executor=f"dask://127.0.0.1:{port}", job_workers=2)
    auth = {"Authorization": "Bearer test-token-0123456789"}
    with distributed.Client(dask_cluster) as observer, distributed.get_task_stream(observer) as tasks, \
            TestClient(create_app(settings, store=store)) as client:
        assert client.get("/health").json()["executor"] == f"dask://127.0.0.1:{port}"
        submitted = {}
        for model in ("case", "school"):
            upload = client.post(f"/models/{model}/measurements", content=case_csv.read_bytes(),
                                 headers={**auth, "Content-Type": "text/csv"}).json()["id"]
            submitted[model] = client.post("/jobs/calibrate", headers=auth, json={
                "model": model, "measurements": upload, "train": SHORT_TRAIN}).json()["id"]
        done = {model: wait_job(client, job_id, timeout_s=120) for model, job_id in submitted.items()}
        for model, job in done.items():
            assert job["status"] == "succeeded", job
            messages = [p["message"] for p in job["progress"]]
            assert messages[1] == f"sent to the Dask cluster at tcp://127.0.0.1:{port}"
            assert "calibrated; writing the run" in messages and messages[-1] == "results written to the store"
            rows = client.get("/queries/calibrated-parameters", params={"model": model}).json()["results"]["bindings"]
            assert len(rows) == len(job["result"]["parameters"]) == len(assemble(store, model).estimated_parameters)
            assert {r["run"]["value"].rsplit("/", 1)[-1] for r in rows} == {job["result"]["run_id"]}
            assert store.run_graph(job["result"]["run_id"]) in store.backend.graphs()
    ran = {t["key"]: t["worker"] for t in tasks.data}
    assert {f"graphtwin-job-{job_id}" for job_id in submitted.values()} <= set(ran), ran
    assert set(ran.values()) == set(dask_cluster.scheduler.workers)


class _RacyResultFuture:
    """A finished future whose ``result(timeout=...)`` fails as distributed's did in CI when the
    result arrived as the timeout expired (an UnboundLocalError inside ``distributed.utils.sync``)."""

    def __init__(self, value):
        self.value, self.polled = value, 0

    def done(self):
        self.polled += 1
        return self.polled > 3  # running for the first polls

    def result(self, timeout=None):
        if timeout is not None:
            raise UnboundLocalError("cannot access local variable 'result' where it is not associated with a value")
        return self.value


class _InlineExecutor:
    """Runs shipped work at submit, handing back a :class:`_RacyResultFuture`."""

    name = "an inline executor"

    def submit(self, function, *args):
        return _RacyResultFuture(function(*args))

    def cancel(self, future):
        raise AssertionError("nothing was cancelled")

    def progress_path(self, job_id):
        return None

    def shutdown(self):
        pass


def test_a_shipped_job_waits_on_done_and_takes_its_result_without_a_timeout(case_store, tmp_path):
    runner = JobRunner(case_store, JobRecords(tmp_path / "jobs"), JOB_KINDS, executor=_InlineExecutor())
    try:
        done = _wait(runner, runner.submit("assemble", AssembleRequest(model="case")).id)
    finally:
        runner.shutdown(wait=True)
    assert done.status == "succeeded", done.error
    assert case_store.assembly_graph("case") in case_store.backend.graphs()


def test_shipped_work_reads_only_the_shipped_graphs_and_writes_nothing_until_the_commit(case_store, tmp_path):
    shipped = ship_job(case_store, "0f" * 16, AssembleRequest(model="case"), None)
    assert isinstance(shipped, ShippedJob) and shipped.measurements == {}
    before = set(case_store.backend.store)
    outcome, nquads, dropped, messages = run_shipped_job(assemble_job, shipped)
    assert set(case_store.backend.store) == before, "the work ran on a scratch store"
    assert [m["message"] for m in messages] == ["matching the signature library"] and dropped == []
    assert outcome.links["assembly_graph"] == case_store.assembly_graph("case").value
    written = GraphStore.embedded(None)
    written.backend.store.load(nquads, format=ox.RdfFormat.N_QUADS)
    assert written.backend.graphs() == [case_store.assembly_graph("case")]
    with pytest.raises(NotFoundError, match="no measurement upload 'abc'"):
        ship_job(case_store, "0f" * 16, CalibrateRequest(model="case", measurements="abc"), None)


def test_an_unreachable_scheduler_is_named(tmp_path):
    with pytest.raises(ValueError, match=r"cannot reach the Dask scheduler at tcp://127.0.0.1:9"):
        DaskJobExecutor("tcp://127.0.0.1:9", connect_timeout_s=0.5)
    with pytest.raises(ValueError, match="threads, processes or dask://HOST:PORT"):
        Settings(data_dir=tmp_path, executor="dask://127.0.0.1")


def test_a_shipped_job_reads_the_model_it_starts_from_and_the_version_it_would_write(case_store, case_csv):
    """A pool process sees only what is shipped to it: the model ``start_from`` names with its runs
    (before: "no such model in the store") and an add-effect job's version already in the store (before:
    the job found none and overwrote it). ``run_shipped_job`` is what the pool process runs."""
    from case_study import case_study_with_effect

    from service.calibration.run import calibrate
    from service.calibration.triples import run_iri
    from service.components.library import SignatureLibrary
    from service.data.windows import parse_window

    first = calibrate(case_store, "case", case_csv, train=parse_window("/2026-01-12T15:50"), seed=0)
    case_store.load_model("case_again", CASE_STUDY)
    request = CalibrateRequest(model="case_again", measurements="day", train="/2026-01-12T15:50", start_from="case")
    outcome, *_ = run_shipped_job(calibrate_job, ship_job(case_store, "j1", request, {"day": case_csv}.__getitem__))
    assert outcome.result["settings"]["start_from"] == {"model": "case", "runs": [run_iri(first.record.run_id).value]}
    library = SignatureLibrary.load()
    case_store.load_model("v", case_study_with_effect(library["ValveLeakage"], EX + "heating_valve"))
    with pytest.raises(ConflictError, match="model v exists with ValveLeakage at .*heating_valve: it is not overwritten"):
        run_shipped_job(add_effect_job, ship_job(case_store, "j2", AddEffectRequest(
            model="case", effect="FanMotorHeat", target=EX + "supply_fan", version="v"), None))
