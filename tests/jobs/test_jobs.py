"""Job records, the runner (progress, one-transaction results, failure, cancel, interruption) and the
job kinds' wiring, with small fake work functions."""

import json
import math
import sys
import threading
import time
import types
from datetime import datetime, timezone

import numpy as np
import pyoxigraph as ox
import pytest
from pydantic import ConfigDict

from service.errors import InputError, NotFoundError, StoreUnavailableError
from service.graph.backend import EmbeddedBackend
from service.graph.store import GraphStore
from service.jobs.deferred_writes import DeferredWrites
from service.jobs.kinds import JOB_KINDS
from service.jobs.records import JobRecord, JobRecords, json_safe
from service.jobs.runner import JobRunner, JobStateError
from service.jobs.work import JobCancelled, JobKind, JobResult
from service.workflows.requests import CalibrateRequest, DiagnoseRequest, FitRequest, JobRequest, ModelRequest

EX = "https://example.org/jobs#"
G1, G2 = ox.NamedNode(EX + "g1"), ox.NamedNode(EX + "g2")


def _triple(subject, value) -> ox.Triple:
    return ox.Triple(subject, ox.NamedNode(EX + "value"), ox.Literal(value))


class CountingBackend(EmbeddedBackend):
    """An in-memory backend that counts its writes that readers see at once: SPARQL updates and
    graph replacements (a replacement of existing graphs stages its data first, then moves it into
    place in one update: one write)."""

    def __init__(self):
        super().__init__(None)
        self.updates = 0

    def update(self, sparql):
        self.updates += 1
        super().update(sparql)

    def replace_graphs(self, graphs):
        before = self.updates
        super().replace_graphs(graphs)
        self.updates = before + 1


class Work(JobRequest):
    """A fake job's request: any fields."""

    model_config = ConfigDict(extra="allow")


class ModelWork(ModelRequest):
    model_config = ConfigDict(extra="allow")


class UploadWork(FitRequest):
    pass


def _kinds(**runs) -> dict[str, JobKind]:
    """Fake job kinds taking a :class:`Work` request."""
    return {name: JobKind(Work, run) for name, run in runs.items()}


def _wait(runner: JobRunner, job_id: str, timeout_s: float = 20.0) -> JobRecord:
    deadline = time.monotonic() + timeout_s
    while (record := runner.get(job_id)).status in ("queued", "running"):
        assert time.monotonic() < deadline, f"job still {record.status}"
        time.sleep(0.01)
    return record


@pytest.fixture
def records(tmp_path) -> JobRecords:
    return JobRecords(tmp_path / "jobs")


@pytest.fixture
def runners():
    made = []

    def make(store, records, kinds, **kwargs) -> JobRunner:
        made.append(JobRunner(store, records, kinds, **kwargs))
        return made[-1]

    yield make
    for runner in made:
        runner.shutdown(wait=True)


# ---------------------------------------------------------------------- records
def test_records_round_trip_atomically_and_only_by_job_id(records):
    record = JobRecord(id="0f" * 16, kind="calibrate", params={"model": "m"},
                       result=json_safe({"rmse": float("nan"), "theta": np.array([1.0, 2.5])}))
    records.save(record)
    assert records.load(record.id) == record
    assert json.loads((records.folder / f"{record.id}.json").read_text())["result"] == {"rmse": None, "theta": [1.0, 2.5]}
    assert [p.name for p in records.folder.iterdir()] == [f"{record.id}.json"]
    assert records.load("../../etc/passwd") is None and records.path("0F" * 16) is None
    assert records.load("1f" * 16) is None


def test_start_up_marks_queued_and_running_records_interrupted(records):
    for job_id, status in (("a1" * 16, "queued"), ("b2" * 16, "running"), ("c3" * 16, "succeeded")):
        records.save(JobRecord(id=job_id, kind="assemble", params={}, status=status))
    assert sorted(records.mark_interrupted()) == ["a1" * 16, "b2" * 16]
    assert records.load("a1" * 16).status == "interrupted" and "was queued" in records.load("a1" * 16).error
    assert records.load("b2" * 16).status == "interrupted" and "was running" in records.load("b2" * 16).error
    assert records.load("c3" * 16).status == "succeeded" and records.load("c3" * 16).error is None
    assert records.mark_interrupted() == []


def test_json_safe_makes_strict_json():
    value = json_safe({"a": np.float64(2.5), "b": [math.inf, np.int64(3)], 4: datetime(2026, 1, 12, tzinfo=timezone.utc)})
    assert value == {"a": 2.5, "b": [None, 3], "4": "2026-01-12T00:00:00+00:00"}
    json.dumps(value, allow_nan=False)


# ---------------------------------------------------------------------- deferred writes
def test_deferred_writes_stay_invisible_until_one_commit():
    backend = CountingBackend()
    backend.replace_graph(G2, [_triple(ox.NamedNode(EX + "old"), "old")])
    backend.updates = 0
    writes = DeferredWrites(backend)
    shared = ox.BlankNode()
    writes.replace_graph(G1, [_triple(shared, "one")])
    writes.replace_graph(G2, [_triple(shared, "two")])
    assert backend.triple_count(G1) == 0 and writes.triple_count(G2) == 1 and backend.updates == 0
    writes.commit()
    assert backend.updates == 1
    rows = backend.query(f"SELECT ?x WHERE {{ GRAPH <{G1.value}> {{ ?x ?p \"one\" }} GRAPH <{G2.value}> {{ ?x ?p \"two\" }} }}")
    assert len(rows) == 1, "a blank node shared by two graphs stays one node"
    assert backend.triple_count(G2) == 1
    writes.drop_graph(G2)
    writes.commit()
    assert G2 not in backend.graphs() and backend.updates == 2
    with pytest.raises(TypeError, match="whole graphs"):
        writes.update("CLEAR ALL")


# ---------------------------------------------------------------------- runner
def test_a_job_reports_progress_and_its_results_appear_together_when_it_succeeds(records, runners):
    backend = CountingBackend()
    store = GraphStore(backend)
    halfway, release = threading.Event(), threading.Event()

    def work(job_store, request, context):
        job_store.write_graph(G1, [_triple(ox.NamedNode(EX + "a"), request.label)])
        context.report("first graph written")
        job_store.write_graph(G2, [_triple(ox.NamedNode(EX + "b"), request.label)])
        halfway.set()
        release.wait(10)
        return JobResult({"value": np.float64(1.5)}, {"graph": G1.value})

    runner = runners(store, records, _kinds(work=work))
    job = runner.submit("work", Work(label="x"))
    assert job.status in ("queued", "running") and records.load(job.id) is not None
    assert halfway.wait(10)
    assert runner.get(job.id).status == "running" and records.load(job.id).status == "running"
    assert backend.graphs() == [] and backend.updates == 0
    release.set()
    done = _wait(runner, job.id)
    assert done.status == "succeeded" and done.result == {"value": 1.5} and done.links == {"graph": G1.value}
    assert [p["message"] for p in done.progress] == ["started", "first graph written", "results written to the store"]
    assert backend.graphs() == sorted([G1, G2], key=lambda g: g.value) and backend.updates == 1
    assert records.load(job.id) == done


@pytest.mark.parametrize("error, expected", [
    (InputError("window 2026-02-01 – 2026-02-02 lies outside the data"), "window 2026-02-01 – 2026-02-02 lies outside the data"),
    (NotFoundError("no measurement upload 'abc'"), "no measurement upload 'abc'"),
    (ValueError("a defect's message"), "internal error: ValueError: a defect's message"),
    (RuntimeError("boom"), "internal error: RuntimeError: boom"),
])
def test_a_failing_job_is_failed_with_its_message_and_writes_nothing(records, runners, error, expected):
    """A user's error (graphtwin's) fails the job with its message; anything else is a defect, said so."""
    store = GraphStore.embedded(None)

    def work(job_store, request, context):
        job_store.write_graph(G1, [_triple(ox.NamedNode(EX + "a"), "partial")])
        raise error

    runner = runners(store, records, _kinds(work=work))
    done = _wait(runner, runner.submit("work", Work()).id)
    assert done.status == "failed" and done.error == expected and done.result is None
    assert store.backend.graphs() == []


def test_cancel_stops_a_running_job_at_its_next_progress_message(records, runners):
    store = GraphStore.embedded(None)
    started, release, reached = threading.Event(), threading.Event(), []

    def work(job_store, request, context):
        job_store.write_graph(G1, [_triple(ox.NamedNode(EX + "a"), "x")])
        started.set()
        release.wait(10)
        context.report("next phase")
        reached.append("after the cancel")
        return JobResult({})

    runner = runners(store, records, _kinds(work=work, quick=lambda s, r, c: JobResult({})))
    running = runner.submit("work", Work())
    assert started.wait(10)
    queued = runner.submit("quick", Work())
    assert runner.cancel(queued.id).status == "cancelled"
    flagged = runner.cancel(running.id)
    assert flagged.status == "running" and flagged.cancel_requested
    release.set()
    done = _wait(runner, running.id)
    assert done.status == "cancelled" and reached == [] and store.backend.graphs() == []
    assert runner.get(queued.id).started is None
    with pytest.raises(JobStateError, match="already ended"):
        runner.cancel(running.id)
    with pytest.raises(NotFoundError):
        runner.cancel("ff" * 16)
    with pytest.raises(NotFoundError, match="unknown job kind"):
        runner.submit("nope", Work())
    with pytest.raises(InputError, match="a work job takes a Work, not a ModelWork"):
        runner.submit("work", ModelWork(model="m"))


def test_resubmit_copies_an_ended_job_and_refuses_an_active_one(records, runners):
    store = GraphStore.embedded(None)
    release = threading.Event()
    runner = runners(store, records, _kinds(wait=lambda s, r, c: JobResult({"waited": release.wait(10), **r.model_dump()})))
    first = runner.submit("wait", Work(n=1))
    with pytest.raises(JobStateError, match="cancel it or wait"):
        runner.resubmit(first.id)
    release.set()
    _wait(runner, first.id)
    again = _wait(runner, runner.resubmit(first.id).id)
    assert again.id != first.id and again.resubmitted_from == first.id and again.result == {"waited": True, "n": 1}


def test_shutdown_marks_queued_jobs_interrupted_and_lets_the_running_one_finish(records):
    started, release = threading.Event(), threading.Event()

    def block(job_store, request, context):
        started.set()
        return JobResult({"released": release.wait(10)})

    runner = JobRunner(GraphStore.embedded(None), records, _kinds(block=block))
    first = runner.submit("block", Work())
    assert started.wait(10)
    second = runner.submit("block", Work())
    runner.shutdown(wait=False)
    assert records.load(second.id).status == "interrupted" and "resubmit" in records.load(second.id).error
    release.set()
    runner.shutdown(wait=True)
    assert records.load(first.id).status == "succeeded" and records.load(first.id).result == {"released": True}


# ---------------------------------------------------------------------- job kinds
class _Report:
    run_id = "m-point-0123abcd"

    def to_dict(self):
        return {"summary": "nothing significant is missing", "score": np.float64(2.0)}


def test_diagnose_job_reports_its_phases_writes_its_graphs_and_stops_on_cancel(records, runners, monkeypatch, tmp_path):
    store = GraphStore.embedded(None)
    data = tmp_path / "data.csv"
    data.write_text("time,x\n")
    calls, gate = [], threading.Event()

    def fake_diagnose(diag_store, model_name, data_path, *, train, test, seed, on_progress, workers, only_when,
                      start_from, rank_effects):
        calls.append((model_name, data_path, train, test, seed, workers, list(only_when), start_from, rank_effects))
        on_progress("calibrating the base model")
        gate.wait(10)
        diag_store.write_graph(diag_store.run_graph("m-point-0123abcd"), [_triple(ox.NamedNode(EX + "r"), "run")])
        on_progress("testing the effect catalog")
        return _Report()

    monkeypatch.setitem(sys.modules, "service.diagnosis.loop", types.SimpleNamespace(diagnose=fake_diagnose))
    kinds = {kind: JOB_KINDS[kind] for kind in ("diagnose", "compare")}
    runner = runners(store, records, kinds, locate_measurements={"u1": data}.__getitem__)
    request = DiagnoseRequest(model="m", measurements="u1", train="/2026-01-12T12:00", test="2026-01-12T12:10/", seed=3,
                              only_when=["x > 1"], start_from="m0")
    gate.set()
    done = _wait(runner, runner.submit("diagnose", request).id)
    assert done.status == "succeeded" and done.result == {"summary": "nothing significant is missing", "score": 2.0}
    assert calls == [("m", data, (None, "2026-01-12T12:00"), ("2026-01-12T12:10", None), 3, 1, ["x > 1"], "m0", True)], \
        "one diagnosis worker, the operating filter and the start passed on"
    assert [p["message"] for p in done.progress][1:3] == ["calibrating the base model", "testing the effect catalog"]
    assert done.links["run_graph"] == store.run_graph("m-point-0123abcd").value
    assert done.links["calibrated_parameters"] == "/queries/calibrated-parameters?model=m"
    assert done.links["report"] == "/runs/m-point-0123abcd-diagnosis/report"  # the job leads to its page
    assert store.run_graph("m-point-0123abcd") in store.backend.graphs()
    compared = _wait(runner, runner.submit("compare", request).id)  # the same, without the effect catalog
    assert compared.status == "succeeded" and calls[-1][-1] is False and calls.pop()[:-1] == calls[0][:-1]
    assert compared.links["report"] == "/runs/m-point-0123abcd-diagnosis/report"

    store.backend.drop_graph(store.run_graph("m-point-0123abcd"))
    gate.clear()
    job = runner.submit("diagnose", request)
    while len(calls) < 2:
        time.sleep(0.01)
    runner.cancel(job.id)
    gate.set()
    assert _wait(runner, job.id).status == "cancelled" and store.backend.graphs() == []


def test_calibrate_job_fails_clearly_when_the_upload_is_gone(records, runners):
    def locate(upload_id):
        raise NotFoundError(f"no measurement upload {upload_id!r}")

    runner = runners(GraphStore.embedded(None), records, {"calibrate": JOB_KINDS["calibrate"]}, locate_measurements=locate)
    done = _wait(runner, runner.submit("calibrate", CalibrateRequest(model="m", measurements="0123456789abcdef")).id)
    assert done.status == "failed" and done.error == "no measurement upload '0123456789abcdef'"
    # a point job's record shows no discrepancy inputs it never used (it echoed the Bayesian default)
    assert done.params["method"] == "point" and done.params["gp_inputs"] is None


def test_work_that_raises_job_cancelled_ends_cancelled(records, runners):
    def give_up(job_store, request, context):
        job_store.write_graph(G1, [_triple(ox.NamedNode(EX + "a"), "x")])
        raise JobCancelled()

    store = GraphStore.embedded(None)
    runner = runners(store, records, _kinds(**{"give-up": give_up}))
    assert _wait(runner, runner.submit("give-up", Work()).id).status == "cancelled" and store.backend.graphs() == []


MODEL_TTL = b"<https://example.org/jobs#fan> a <https://saref.etsi.org/saref4bldg/Fan> ."


def test_a_job_whose_model_is_replaced_while_it_runs_writes_nothing(records, runners):
    """The model is replaced (PUT /models/NAME) while a job on it runs: its results describe a model
    the store no longer holds, so they are not written and the job says why."""
    store = GraphStore.embedded(None)
    store.load_model("m", MODEL_TTL)
    started, release = threading.Event(), threading.Event()

    def work(job_store, request, context):
        job_store.write_graph(job_store.assembly_graph(request.model), [_triple(ox.NamedNode(EX + "a"), "old")])
        started.set()
        release.wait(10)
        return JobResult({})

    runner = runners(store, records, {"work": JobKind(ModelWork, work)})
    job = runner.submit("work", ModelWork(model="m"))
    assert started.wait(10)
    store.load_model("m", MODEL_TTL + b'\n<https://example.org/jobs#fan> <http://www.w3.org/2000/01/rdf-schema#label> "new" .')
    release.set()
    done = _wait(runner, job.id)
    assert done.status == "failed" and "the model 'm' changed while the job ran" in done.error
    assert store.assembly_graph("m") not in store.backend.graphs()


def test_of_two_jobs_creating_the_same_model_version_the_second_does_not_overwrite_the_first(records, runners):
    store = GraphStore.embedded(None)
    store.load_model("m", MODEL_TTL)
    both_started, release = threading.Barrier(2), threading.Event()

    def work(job_store, request, context):
        job_store.write_graph(job_store.model_graph("m+Effect"), [_triple(ox.NamedNode(EX + "a"), request.label)])
        both_started.wait(10)
        release.wait(10)
        return JobResult({})

    runner = runners(store, records, {"work": JobKind(ModelWork, work)}, max_workers=2)
    first, second = (runner.submit("work", ModelWork(model="m", label=label)) for label in ("first", "second"))
    time.sleep(0.2)
    release.set()
    done = sorted((_wait(runner, job.id) for job in (first, second)), key=lambda r: r.status)
    assert [r.status for r in done] == ["failed", "succeeded"]
    assert "was written by another job while this one ran: not overwritten" in done[0].error
    [label] = [t.object.value for t in store.graph_triples(store.model_graph("m+Effect"))]
    assert label == done[1].params["label"]


def test_a_job_error_names_the_upload_not_the_servers_file_path(records, runners, tmp_path):
    upload = "0123456789abcdef"
    csv = tmp_path / "measurements" / "m" / f"{upload}.csv"

    def work(job_store, request, context):
        raise InputError(f"window 2030-01-01 – 2030-02-01 lies outside the data {csv} (2026-01-12 – 2026-01-13)")

    runner = runners(GraphStore.embedded(None), records, {"work": JobKind(UploadWork, work)})
    done = _wait(runner, runner.submit("work", UploadWork(model="m", measurements=upload)).id)
    assert done.error == f"window 2030-01-01 – 2030-02-01 lies outside the data upload {upload} (2026-01-12 – 2026-01-13)"


def test_result_links_quote_a_model_name_with_a_plus():
    """``model+Effect`` (what add-effect names a version) in a query string: '+' would read as a space."""
    from service.workflows.runs import result_links

    links = result_links(GraphStore.embedded(None), "case+FanMotorHeat", "r1")
    assert links["calibrated_parameters"] == "/queries/calibrated-parameters?model=case%2BFanMotorHeat"
    assert links["sensor_metrics"] == "/queries/sensor-metrics?model=case%2BFanMotorHeat"


class FailingAfterWork(EmbeddedBackend):
    """A backend whose store stops answering once ``fail`` is set (an external endpoint gone)."""

    def __init__(self):
        super().__init__(None)
        self.fail = False

    def graphs(self):
        if self.fail:
            raise StoreUnavailableError("the endpoint http://store:7878 answered 502")
        return super().graphs()


def test_a_store_that_fails_after_the_work_is_done_fails_the_job_with_the_cause(records, runners):
    """Before, the check that the model had not changed ran outside the job's error handling: the job
    stayed running for good, neither cancellable nor resubmittable."""
    backend = FailingAfterWork()
    store = GraphStore(backend)

    def work(job_store, request, context):
        job_store.write_graph(G1, [_triple(ox.NamedNode(EX + "a"), "x")])
        backend.fail = True
        return JobResult({})

    runner = runners(store, records, _kinds(work=work))
    done = _wait(runner, runner.submit("work", Work()).id)
    assert done.status == "failed" and "answered 502" in done.error, done
    backend.fail = False
    assert backend.graphs() == [] and runner.resubmit(done.id).status in ("queued", "running")


def test_an_interrupting_shutdown_marks_running_and_queued_jobs_and_returns_at_once(records):
    """A service told to stop (SIGTERM) does not wait for a job's work: the running job and the queued
    one are marked interrupted (resubmit them), and what the running work still returns is dropped."""
    store = GraphStore.embedded(None)
    started, release = threading.Event(), threading.Event()

    def block(job_store, request, context):
        started.set()
        release.wait(30)
        job_store.write_graph(G1, [_triple(ox.NamedNode(EX + "a"), "late")])
        return JobResult({"late": True})

    runner = JobRunner(store, records, _kinds(block=block))
    running, queued = runner.submit("block", Work()), None
    assert started.wait(10)
    queued = runner.submit("block", Work())
    began = time.monotonic()
    runner.shutdown(interrupt=True)
    assert time.monotonic() - began < 1.0
    for job, when in ((running, "while the job ran"), (queued, "before the job started")):
        assert records.load(job.id).status == "interrupted" and when in records.load(job.id).error
    with pytest.raises(JobStateError, match="stopping"):
        runner.submit("block", Work())
    release.set()
    time.sleep(0.3)  # the abandoned work ends: its results are not written, its record stays interrupted
    assert store.backend.graphs() == [] and records.load(running.id).status == "interrupted"
