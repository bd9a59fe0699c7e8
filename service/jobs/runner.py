"""Long-running work of the HTTP service (assemble, calibrate, diagnose, add-effect) as jobs.

**Records.** A :class:`JobRecord` (kind, parameters, status, progress messages, result, links) is a
JSON file ``<jobs dir>/<id>.json``, rewritten atomically (a temporary file, then ``os.replace``) on
every change, so a crash leaves the previous version, never half of one. Status moves
``queued → running → succeeded | failed | cancelled``; at start-up, :meth:`JobRecords.mark_interrupted`
marks what a stopped process left ``queued`` or ``running`` as ``interrupted`` (resubmit it: a job
is never left "running" forever and a finished result is never lost).

**Runner.** :class:`JobRunner` runs each job on a thread of its own
(:class:`~concurrent.futures.ThreadPoolExecutor`, ``max_workers`` at a time). Where the work runs
depends on its ``executor`` (:func:`job_executor`, ``GRAPHTWIN_EXECUTOR`` / ``graphtwin serve --executor``):

* ``threads``: on that thread, reading the live store (pyoxigraph releases the GIL while it
  queries and the calibration spends its time in numpy, so threads overlap well);
* ``processes`` (the service's default): in a local process pool (:class:`ProcessJobExecutor`);
* ``dask://HOST:PORT``: on the workers of a Dask distributed cluster (:class:`DaskJobExecutor`),
  e.g. a portfolio of buildings calibrated in parallel.

The embedded on-disk store is opened by one process only (Oxigraph locks it), so work that runs
elsewhere never touches it: the job's thread ships a :class:`ShippedJob` (the graphs the job reads,
``GraphStore.matching_dataset(params["model"])``, as N-Quads, and the bytes of its measurement
upload ``params["measurements"]``), :func:`run_shipped_job` runs the work against a scratch
in-memory store holding them and sends back the result and the graphs it wrote (N-Quads), and the
job's thread commits those as below. Progress messages of shipped work arrive with its result; a
cancel drops the remote task at once: a running pool process is terminated, a running Dask task
finishes in the background and its results are discarded.

**Results.** A job reads the store as it is and writes through :class:`DeferredWrites`: every graph
it writes is kept in memory and committed in ONE update when the job ends, before its status says
``succeeded``. A reader sees all of a job's results or none, and they are queryable the moment the
job reports success; a failed or cancelled job writes nothing. (A job never reads a graph it wrote
itself; such a read would see the graph as it was before the job.)

**Cancel.** A queued job is cancelled at once. A running one is flagged: work on the job's thread
stops at its next progress message (:meth:`JobContext.report` raises :class:`JobCancelled`), or
runs to its end, and its results are then discarded; shipped work is dropped as above. A cancel
that arrives while the results are being committed waits for the commit and is then refused: the
job has ended.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from enum import StrEnum
from multiprocessing import get_context
from pathlib import Path
from urllib.parse import quote, urlsplit

import numpy as np
import pyoxigraph as ox

from service.model.assembly import EffectRequest, assemble, recorded_effects
from service.model.summary import assembly_to_dict
from service.model.assembly_triples import assembly_iri, assembly_triples
from service.calibration.model_data import DEFAULT_GP_INPUTS
from service.calibration.run import calibrate, model_version, parse_window
from service.model.effect_recording import applied_effect_triples
from service.graph.namespaces import GT
from service.graph.ntriples import triple_list
from service.runtime import exit_with_parent
from service.settings import check_executor
from service.components.library import SignatureLibrary
from service.graph.store import GraphStore, parse_rdf

__all__ = [
    "JobStatus", "JobRecord", "JobRecords", "JobResult", "JobContext", "JobCancelled", "JobStateError",
    "ShippedWorkError", "DeferredWrites", "JobRunner", "JobKind", "ShippedJob", "ShippedContext", "run_shipped_job", "ProcessJobExecutor",
    "DaskJobExecutor", "job_executor", "assemble_job", "calibrate_job", "diagnose_job",
    "add_effect_job", "json_safe",
]

log = logging.getLogger("graphtwin.jobs")
_JOB_ID = re.compile(r"^[0-9a-f]{32}$")


class JobStatus(StrEnum):
    """The states of a job (stored as their text)."""

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"
    INTERRUPTED = "interrupted"


#: States in which a job still has work to do.
ACTIVE = frozenset({JobStatus.QUEUED, JobStatus.RUNNING})


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def json_safe(value):
    """``value`` with numpy scalars/arrays as Python numbers/lists, NaN and ±inf as None, datetimes as
    ISO text: what strict JSON (and the API's responses) can carry."""
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, np.ndarray)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, datetime):
        return value.isoformat()
    if value is None or isinstance(value, (bool, int, str)):
        return value
    return str(value)


@dataclass
class JobRecord:
    """One job as persisted; ``progress`` holds ``{"time", "message"}`` entries, oldest first."""

    id: str
    kind: str
    params: dict
    status: str = JobStatus.QUEUED
    created: str = field(default_factory=_now)
    started: str | None = None
    finished: str | None = None
    progress: list[dict] = field(default_factory=list)
    result: dict | None = None
    links: dict[str, str] = field(default_factory=dict)
    error: str | None = None
    cancel_requested: bool = False
    resubmitted_from: str | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> JobRecord:
        return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})


class JobRecords:
    """Job records as JSON files in ``folder`` (created if missing)."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)

    def path(self, job_id: str) -> Path | None:
        """The record's file, or None for a text that is no job id (never a path outside ``folder``)."""
        return self.folder / f"{job_id}.json" if _JOB_ID.match(job_id or "") else None

    def save(self, record: JobRecord) -> None:
        """Write ``record`` atomically: a reader (or a restart) sees the old file or the new one."""
        text = json.dumps(json_safe(record.to_dict()), indent=1, allow_nan=False)
        handle, temporary = tempfile.mkstemp(dir=self.folder, prefix=f".{record.id}.", suffix=".tmp")
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as out:
                out.write(text)
            os.replace(temporary, self.folder / f"{record.id}.json")
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise

    def load(self, job_id: str) -> JobRecord | None:
        path = self.path(job_id)
        if path is None or not path.is_file():
            return None
        return JobRecord.from_dict(json.loads(path.read_text(encoding="utf-8")))

    def all(self) -> list[JobRecord]:
        """Every record, oldest first."""
        records = [self.load(p.stem) for p in self.folder.glob("*.json")]
        return sorted((r for r in records if r is not None), key=lambda r: r.created)

    def mark_interrupted(self) -> list[str]:
        """Mark records a stopped process left queued or running as ``interrupted``; their ids."""
        marked = []
        for record in self.all():
            if record.status in ACTIVE:
                record.error = f"the service stopped while the job was {record.status}; resubmit it"
                record.status, record.finished = JobStatus.INTERRUPTED, _now()
                self.save(record)
                marked.append(record.id)
        return marked


class JobCancelled(Exception):
    """Raised inside a job's work when its cancellation was requested."""


class ShippedWorkError(Exception):
    """Shipped work raised something other than a bad-input error (a bug): its type and message as
    text, since not every exception survives the way back from a pool process or a Dask worker."""


class JobStateError(Exception):
    """The operation does not apply to the job in its current state (the message says why)."""


@dataclass(frozen=True)
class JobResult:
    """What a job's work returns: a JSON-able ``result`` and ``links`` to what it wrote."""

    result: dict
    links: dict[str, str] = field(default_factory=dict)


class DeferredWrites:
    """A :class:`~service.graph.store.SparqlBackend` that reads ``backend`` and keeps whole-graph writes
    until :meth:`commit` writes them in one transaction (the backend's ``replace_graphs``: blank
    nodes shared between graphs stay shared).

    Reads go to ``backend`` unchanged: a graph written here is not seen before the commit.
    """

    def __init__(self, backend):
        self.backend = backend
        self._graphs: dict[ox.NamedNode, list[ox.Triple]] = {}

    def query(self, sparql, *, substitutions=None, default_graph=None):
        return self.backend.query(sparql, substitutions=substitutions, default_graph=default_graph)

    def update(self, sparql):
        raise TypeError("a job writes whole graphs (replace_graph, drop_graph); a SPARQL Update is not deferred")

    def replace_graph(self, graph, triples):
        self._graphs[graph] = list(triples)

    def replace_graphs(self, graphs):
        for graph, triples in graphs.items():
            self.replace_graph(graph, triple_list(triples))

    def load_graph(self, graph, data, format, *, base_iri=None, source_name="<data>"):
        triples = parse_rdf(data, format, source_name, base_iri)
        self.replace_graph(graph, triples)
        return len(triples)

    def drop_graph(self, graph):
        self._graphs[graph] = []

    def graphs(self):
        return self.backend.graphs()

    def dump(self, graph, format):
        return self.backend.dump(graph, format)

    def triple_count(self, graph):
        return self.backend.triple_count(graph)

    def written_graphs(self) -> list[ox.NamedNode]:
        """The graphs kept for the commit (written or dropped)."""
        return list(self._graphs)

    def shipped(self) -> tuple[bytes, list[str]]:
        """The kept graphs as one N-Quads document (blank nodes shared between graphs stay shared)
        and the IRIs of the graphs kept empty (drops): what shipped work sends back."""
        quads = [ox.Quad(t.subject, t.predicate, t.object, graph) for graph, triples in self._graphs.items() for t in triples]
        return ox.serialize(quads, format=ox.RdfFormat.N_QUADS), [g.value for g, t in self._graphs.items() if not t]

    def keep_shipped(self, nquads: bytes, dropped: list[str]) -> None:
        """Keep what :meth:`shipped` made elsewhere, as if the work had written it here."""
        graphs: dict[ox.NamedNode, list[ox.Triple]] = {ox.NamedNode(g): [] for g in dropped}
        for quad in ox.parse(nquads, format=ox.RdfFormat.N_QUADS):
            graphs.setdefault(quad.graph_name, []).append(quad.triple)
        self._graphs.update(graphs)

    def commit(self) -> None:
        """Write every kept graph in one transaction; nothing to do when nothing was written."""
        if not self._graphs:
            return
        self.backend.replace_graphs(self._graphs)
        self._graphs.clear()


def _public(message: str, params: Mapping) -> str:
    """``message`` with the server's file path of the job's measurement upload (where the service or a
    worker keeps it) written as the upload's id, all a client knows of it."""
    upload = params.get("measurements")
    if not upload:
        return message
    return re.sub(r"\S*" + re.escape(str(upload)) + r"\.csv", f"upload {upload}", message)


class JobContext:
    """Handed to a job's work: report progress, learn about a cancel request, find its measurements."""

    def __init__(self, runner: JobRunner, job_id: str):
        self._runner, self.job_id = runner, job_id

    def measurements(self, upload_id: str) -> Path:
        """The CSV of measurement upload ``upload_id``.

        :raises KeyError: no such upload.
        """
        if self._runner.locate_measurements is None:
            raise KeyError(f"no measurement upload {upload_id!r}: this runner keeps no uploads")
        return self._runner.locate_measurements(upload_id)

    @property
    def cancel_requested(self) -> bool:
        return self._runner.get(self.job_id).cancel_requested

    def report(self, message: str) -> None:
        """Record a progress message; raises :class:`JobCancelled` when a cancel was requested."""
        self._runner._progress(self.job_id, message)
        if self.cancel_requested:
            raise JobCancelled()


#: A job kind: ``work(store, params, context) -> JobResult``; ``store`` writes through DeferredWrites.
#: Kinds run by a process pool or Dask are pickled by reference: module-level functions.
JobKind = Callable[[GraphStore, dict, JobContext], JobResult]


# ---------------------------------------------------------------------- shipped work
@dataclass(frozen=True)
class ShippedJob:
    """Everything a job needs away from the server (picklable): its ``params``, the graphs it reads
    (``dataset``, N-Quads) and the bytes of its measurement uploads by upload id."""

    job_id: str
    params: dict
    dataset: bytes
    measurements: dict[str, bytes] = field(default_factory=dict)


class ShippedContext:
    """The :class:`JobContext` of shipped work: progress messages are kept (they travel back with
    the result), measurements are the shipped bytes written to ``folder``."""

    cancel_requested = False

    def __init__(self, job: ShippedJob, folder: Path):
        self.job_id, self._job, self._folder = job.job_id, job, Path(folder)
        self.messages: list[dict] = []

    def report(self, message: str) -> None:
        self.messages.append({"time": _now(), "message": message})

    def measurements(self, upload_id: str) -> Path:
        if upload_id not in self._job.measurements:
            raise KeyError(f"no measurement upload {upload_id!r}")
        path = self._folder / f"{upload_id}.csv"
        if not path.is_file():
            path.write_bytes(self._job.measurements[upload_id])
        return path


def run_shipped_job(work: JobKind, job: ShippedJob) -> tuple[JobResult, bytes, list[str], list[dict]]:
    """Run ``work`` on a scratch in-memory store holding ``job.dataset``: in a pool process or on a
    Dask worker. Returns the result, the graphs written (:meth:`DeferredWrites.shipped`) and the
    progress messages. Errors travel back in types that always unpickle: bad input as a ``KeyError``
    or ``ValueError`` with the original message, anything else as :class:`ShippedWorkError`."""
    scratch = GraphStore.embedded(None)
    scratch.backend.store.load(job.dataset, format=ox.RdfFormat.N_QUADS)
    writes = DeferredWrites(scratch.backend)
    with tempfile.TemporaryDirectory(prefix="graphtwin-job-") as folder:
        context = ShippedContext(job, Path(folder))
        try:
            outcome = work(GraphStore(writes), job.params, context)
        except (JobCancelled, FileNotFoundError, FileExistsError):
            raise
        except KeyError as exc:  # bad input: the same category and message, in a type that unpickles
            raise KeyError(*exc.args[:1]) from None
        except ValueError as exc:
            raise ValueError(str(exc)) from None
        except Exception as exc:
            raise ShippedWorkError(f"{type(exc).__name__}: {exc}") from None
    nquads, dropped = writes.shipped()
    return outcome, nquads, dropped, context.messages


def ship_job(store: GraphStore, job_id: str, params: dict,
             locate_measurements: Callable[[str], Path] | None) -> ShippedJob:
    """What :func:`run_shipped_job` needs for a job on ``store``: the graphs of
    ``store.matching_dataset(params["model"])``, the upload ``params["measurements"]``, and where the
    job reads another model, its graphs too: ``start_from``'s, with its assembly and its calibration
    runs (the values it starts from), and an add-effect job's version when it exists (which effects
    it records decides whether the job may write it).

    :raises KeyError: the upload does not exist; :raises ValueError: an invalid model name.
    """
    graphs: list[ox.NamedNode] = []
    if "model" in params:
        graphs += store.matching_dataset(params["model"])
    start_from = params.get("start_from")
    if start_from and store.has_model(start_from):
        graphs += [*store.matching_dataset(start_from), store.assembly_graph(start_from)]
        graphs += [row["g"] for row in store.run_named_query("calibration-run-graphs", model=start_from)]
    if "effect" in params and "model" in params and store.has_model(version := effect_version_name(params)):
        graphs += store.matching_dataset(version)
    quads = [ox.Quad(t.subject, t.predicate, t.object, graph)
             for graph in dict.fromkeys(graphs) for t in store.graph_triples(graph)]
    files = {}
    upload = params.get("measurements")
    if upload is not None:
        if locate_measurements is None:
            raise KeyError(f"no measurement upload {upload!r}: this runner keeps no uploads")
        files[upload] = Path(locate_measurements(upload)).read_bytes()
    return ShippedJob(job_id, dict(params), ox.serialize(quads, format=ox.RdfFormat.N_QUADS), files)


class ProcessJobExecutor:
    """Shipped work in ``max_workers`` local processes (started with ``spawn``: the server's threads
    and its open store are not copied into them), each in a single-process pool of its own, so one
    job's process can be stopped without touching the others': a cancelled running job
    (:meth:`cancel`) has its process terminated and its slot gets a new one. A pool whose worker
    died (killed, out of memory) cannot take work: the job that ran there fails, and the next one in
    that slot gets a new pool. A job goes to the slot with the least work (the runner runs at most
    as many jobs at once as there are slots)."""

    def __init__(self, max_workers: int = 1):
        self.name = f"a local process pool ({max_workers} process{'es' if max_workers > 1 else ''})"
        self._slots = [self._new_pool() for _ in range(max_workers)]
        self._submitted: list[list[Future]] = [[] for _ in range(max_workers)]
        self._lock = threading.Lock()

    @staticmethod
    def _new_pool() -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=1, mp_context=get_context("spawn"), initializer=exit_with_parent)

    def submit(self, function, *args) -> Future:
        with self._lock:
            for futures in self._submitted:
                futures[:] = [f for f in futures if not f.done()]
            slot = min(range(len(self._slots)), key=lambda i: len(self._submitted[i]))
            try:
                future = self._slots[slot].submit(function, *args)
            except BrokenProcessPool:
                log.warning("a job process pool broke (its worker died): starting a new one")
                self._replace(slot)
                future = self._slots[slot].submit(function, *args)
            self._submitted[slot].append(future)
            return future

    def cancel(self, future: Future) -> None:
        """Drop ``future``'s work: cancelled if it has not started, else its process is terminated
        (work queued behind it in the same slot fails with it) and the slot gets a new one."""
        if future.cancel() or future.done():
            return
        with self._lock:
            slot = next((i for i, futures in enumerate(self._submitted) if future in futures), None)
            if slot is not None and not future.done():
                self._replace(slot)

    def _replace(self, slot: int) -> None:
        _stop_pool(self._slots[slot])
        self._slots[slot], self._submitted[slot] = self._new_pool(), []

    def shutdown(self) -> None:
        """Stop every slot's pool and worker: a job still running there is abandoned, not left to
        run on in an orphaned process after the service exits."""
        with self._lock:
            for pool in self._slots:
                _stop_pool(pool)


def _stop_pool(pool: ProcessPoolExecutor, timeout_s: float = 10.0) -> None:
    """Shut ``pool`` down and terminate its workers, waiting up to ``timeout_s`` for them to exit."""
    workers = list((pool._processes or {}).values())  # the pool keeps no public handle on them
    pool.shutdown(wait=False, cancel_futures=True)
    for worker in workers:
        worker.terminate()
    deadline = time.monotonic() + timeout_s
    for worker in workers:
        # join returns early when the pool's own thread reaps the worker first; its exit code follows
        while worker.exitcode is None and time.monotonic() < deadline:
            worker.join(timeout=0.05)


class DaskJobExecutor:
    """Shipped work on a Dask distributed cluster: ``address`` is the scheduler's (``tcp://HOST:PORT``),
    or a ``distributed.Client`` to use as it is (tests: a ``LocalCluster``'s). Workers need graphtwin
    installed (they import ``service.jobs.runner``); nothing else is shared with them."""

    def __init__(self, address, *, connect_timeout_s: float = 10.0):
        try:
            from distributed import Client
        except ImportError:  # pragma: no cover - depends on the installation
            raise ValueError("the Dask executor needs the distributed package: pip install 'graphtwin[dask]'") from None
        if isinstance(address, Client):
            self.client, self._own_client = address, False
        else:
            try:
                self.client, self._own_client = Client(address, timeout=connect_timeout_s, set_as_default=False), True
            except OSError as exc:
                raise ValueError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        self.name = f"the Dask cluster at {self.client.scheduler.address}"

    def submit(self, function, work: JobKind, job: ShippedJob):
        return self.client.submit(function, work, job, pure=False, key=f"graphtwin-job-{job.job_id}")

    def cancel(self, future) -> None:
        """Drop ``future``'s task (a running one finishes on its worker; its result is discarded)."""
        future.cancel()

    def shutdown(self) -> None:
        if self._own_client:
            self.client.close()


def job_executor(spec: str, *, max_workers: int = 1):
    """The executor ``spec`` names (:func:`check_executor`): None for ``threads`` (work runs on the
    job's thread), a :class:`ProcessJobExecutor` or a :class:`DaskJobExecutor`."""
    check_executor(spec)
    if spec == "threads":
        return None
    if spec == "processes":
        return ProcessJobExecutor(max_workers)
    parts = urlsplit(spec)
    return DaskJobExecutor(f"tcp://{parts.hostname}:{parts.port}")


class JobRunner:
    """Runs jobs of the registered ``kinds`` on ``store``, ``max_workers`` at a time; see the module
    docstring for threads, results and cancellation. Records persist through ``records``."""

    def __init__(self, store: GraphStore, records: JobRecords, kinds: Mapping[str, JobKind], *, max_workers: int = 1,
                 locate_measurements: Callable[[str], Path] | None = None, executor=None):
        """:param locate_measurements: upload id → CSV path (:meth:`JobContext.measurements`).
        :param executor: None (work on the job's thread), a :class:`ProcessJobExecutor` or a
            :class:`DaskJobExecutor` (see :func:`job_executor`); :meth:`shutdown` shuts it down."""
        self.store, self.records, self.kinds = store, records, dict(kinds)
        self.locate_measurements, self.executor = locate_measurements, executor
        self._lock = threading.RLock()
        self._jobs = {r.id: r for r in records.all()}
        self._futures: dict[str, Future] = {}
        self._executor = ThreadPoolExecutor(max_workers=max_workers, thread_name_prefix="graphtwin-job")

    # ------------------------------------------------------------------ reading
    def get(self, job_id: str) -> JobRecord | None:
        with self._lock:
            record = self._jobs.get(job_id)
            return JobRecord.from_dict(record.to_dict()) if record is not None else None

    def list(self) -> list[JobRecord]:
        with self._lock:
            return [JobRecord.from_dict(r.to_dict()) for r in sorted(self._jobs.values(), key=lambda r: r.created)]

    def active_count(self) -> int:
        with self._lock:
            return sum(r.status in ACTIVE for r in self._jobs.values())

    # ------------------------------------------------------------------ changing
    def submit(self, kind: str, params: dict, *, resubmitted_from: str | None = None) -> JobRecord:
        """Queue a job; returns its record at once.

        :raises KeyError: an unknown kind.
        """
        if kind not in self.kinds:
            raise KeyError(f"unknown job kind {kind!r}; known: {', '.join(sorted(self.kinds))}")
        record = JobRecord(id=uuid.uuid4().hex, kind=kind, params=json_safe(params), resubmitted_from=resubmitted_from)
        with self._lock:
            self._jobs[record.id] = record
            self.records.save(record)
            self._futures[record.id] = self._executor.submit(self._run, record.id)
        return self.get(record.id)

    def resubmit(self, job_id: str) -> JobRecord:
        """A new job with the kind and parameters of a finished one.

        :raises KeyError: an unknown job; :raises JobStateError: the job is still queued or running.
        """
        old = self.get(job_id)
        if old is None:
            raise KeyError(job_id)
        if old.status in ACTIVE:
            raise JobStateError(f"job {job_id} is {old.status}: cancel it or wait for it before resubmitting")
        return self.submit(old.kind, old.params, resubmitted_from=job_id)

    def cancel(self, job_id: str) -> JobRecord:
        """Cancel a queued job at once, flag a running one (module docstring).

        :raises KeyError: an unknown job; :raises JobStateError: the job has already ended.
        """
        with self._lock:
            record = self._jobs.get(job_id)
            if record is None:
                raise KeyError(job_id)
            if record.status not in ACTIVE:
                raise JobStateError(f"job {job_id} has already ended ({record.status})")
            future = self._futures.get(job_id)
            if record.status == JobStatus.QUEUED and future is not None and future.cancel():
                record.status, record.finished = JobStatus.CANCELLED, _now()
                record.progress.append({"time": _now(), "message": "cancelled before it started"})
            else:
                record.cancel_requested = True
                record.progress.append({"time": _now(), "message": "cancel requested: the results will be discarded"})
            self.records.save(record)
        return self.get(job_id)

    def shutdown(self, wait: bool = True) -> None:
        """Stop taking jobs: queued ones are marked ``interrupted``; with ``wait``, running ones end first."""
        self._executor.shutdown(wait=False, cancel_futures=True)
        with self._lock:
            for job_id, future in self._futures.items():
                record = self._jobs[job_id]
                if future.cancelled() and record.status == JobStatus.QUEUED:
                    record.status, record.finished = JobStatus.INTERRUPTED, _now()
                    record.error = "the service stopped before the job started; resubmit it"
                    self.records.save(record)
        if wait:
            self._executor.shutdown(wait=True)
            if self.executor is not None:
                self.executor.shutdown()

    # ------------------------------------------------------------------ internals
    def _model_state(self, params: Mapping) -> tuple[str | None, frozenset[str]]:
        """What a job's results rest on: the version of the model it reads (None without one) and the
        model graphs the store holds."""
        version = model_version(self.store, params["model"]) if "model" in params and self.store.has_model(
            params["model"]) else None
        prefix = self.store.model_graph("x").value[:-1]
        return version, frozenset(g.value for g in self.store.backend.graphs() if g.value.startswith(prefix))

    def _conflict(self, params: Mapping, before: tuple[str | None, frozenset[str]], writes: DeferredWrites) -> str | None:
        """Why the job's results must not be written (called under the lock, before the commit): its
        model changed while it ran (another load replaced it), or a model graph it would create was
        created meanwhile (two add-effect jobs naming the same version); None when they may be."""
        version, models = self._model_state(params)
        if version != before[0]:
            return (f"the model {params['model']!r} changed while the job ran (version {before[0]} → {version}): its "
                    "results would describe a model the store no longer holds; resubmit the job")
        created = sorted(g.value for g in writes.written_graphs() if g.value in models - before[1])
        if created:
            return (f"{', '.join(created)} was written by another job while this one ran: not overwritten; resubmit "
                    "with another version name")
        return None

    def _progress(self, job_id: str, message: str) -> None:
        with self._lock:
            record = self._jobs[job_id]
            record.progress.append({"time": _now(), "message": message})
            self.records.save(record)

    def _finish(self, job_id: str, status: str, *, error: str | None = None, message: str | None = None) -> None:
        with self._lock:
            record = self._jobs[job_id]
            record.status, record.finished, record.error = status, _now(), error
            if message:
                record.progress.append({"time": record.finished, "message": message})
            self.records.save(record)

    def _run_shipped(self, job_id: str, kind: str, params: dict, writes: DeferredWrites) -> JobResult:
        """Run the job's work on ``self.executor``; wait for it, dropping it when a cancel is requested."""
        future = self.executor.submit(run_shipped_job, self.kinds[kind],
                                      ship_job(self.store, job_id, params, self.locate_measurements))
        self._progress(job_id, f"sent to {self.executor.name}")
        # poll done() rather than result(timeout=...): distributed's result() can lose a result that
        # arrives as its timeout expires (an UnboundLocalError inside distributed.utils.sync)
        while not future.done():
            if self.get(job_id).cancel_requested:
                self.executor.cancel(future)
                raise JobCancelled()
            time.sleep(0.2)
        outcome, nquads, dropped, messages = future.result()
        with self._lock:
            self._jobs[job_id].progress.extend(messages)
        writes.keep_shipped(nquads, dropped)
        return outcome

    def _run(self, job_id: str) -> None:
        with self._lock:
            record = self._jobs[job_id]
            if record.status != JobStatus.QUEUED:
                return
            record.status, record.started = JobStatus.RUNNING, _now()
            record.progress.append({"time": record.started, "message": "started"})
            self.records.save(record)
            kind, params = record.kind, dict(record.params)
        writes = DeferredWrites(self.store.backend)
        try:
            before = self._model_state(params)
            if self.executor is None:
                outcome = self.kinds[kind](GraphStore(writes), params, JobContext(self, job_id))
            else:
                outcome = self._run_shipped(job_id, kind, params, writes)
        except JobCancelled:
            self._finish(job_id, JobStatus.CANCELLED, message="cancelled; nothing was written")
            return
        except (ValueError, KeyError, FileNotFoundError, FileExistsError) as exc:
            message = _public(str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc), params)
            self._finish(job_id, JobStatus.FAILED, error=message, message="failed; nothing was written")
            return
        except Exception as exc:  # a bug, not the user's input: keep the service up and say so
            log.exception("job %s (%s) failed", job_id, kind)
            described = str(exc) if isinstance(exc, ShippedWorkError) else f"{type(exc).__name__}: {exc}"
            self._finish(job_id, JobStatus.FAILED, error=f"internal error: {described}",
                         message="failed; nothing was written")
            return
        with self._lock:
            record = self._jobs[job_id]
            if record.cancel_requested:
                self._finish(job_id, JobStatus.CANCELLED, message="cancelled; the results were discarded")
                return
            conflict = self._conflict(params, before, writes)
            if conflict:
                self._finish(job_id, JobStatus.FAILED, error=conflict, message="failed; nothing was written")
                return
            record.result = json_safe(outcome.result)
            try:
                writes.commit()
            except Exception as exc:
                log.exception("job %s (%s) could not write its results", job_id, kind)
                record.result = None
                self._finish(job_id, JobStatus.FAILED, error=f"writing the results failed: {exc}")
                return
            record.links = dict(outcome.links)
            self._finish(job_id, JobStatus.SUCCEEDED, message="results written to the store")


# ---------------------------------------------------------------------- job kinds
def _window(text: str | None):
    return parse_window(text) if text is not None else None


def assemble_job(store: GraphStore, params: dict, context: JobContext) -> JobResult:
    """``{"model"}``: assemble the model and write its assembly graph."""
    model = params["model"]
    context.report("matching the signature library")
    assembled = assemble(store, model)
    store.write_graph(store.assembly_graph(model), assembly_triples(assembled, model))
    return JobResult(assembly_to_dict(assembled), {
        "model": f"/models/{model}", "assembly_graph": store.assembly_graph(model).value,
    })


def _result_links(store: GraphStore, model: str, run_id: str) -> dict[str, str]:
    return {
        "run_graph": store.run_graph(run_id).value,
        "calibrated_parameters": f"/queries/calibrated-parameters?model={quote(model, safe='')}",
        "sensor_metrics": f"/queries/sensor-metrics?model={quote(model, safe='')}",  # a '+' in a name is no space
    }


def calibrate_job(store: GraphStore, params: dict, context: JobContext) -> JobResult:
    """``{"model", "measurements", "train", "test", "method", "seed", "only_when", "gp_inputs", "start_from"}``
    (windows as ``START/END``): :func:`service.calibration.run.calibrate` on the uploaded CSV
    ``context.measurements(id)``."""
    model = params["model"]
    data = context.measurements(params["measurements"])
    context.report(f"calibrating ({params.get('method', 'point')})")
    outcome = calibrate(store, model, data, train=parse_window(params.get("train") or "/"),
                        test=_window(params.get("test")), method=params.get("method", "point"),
                        seed=int(params.get("seed", 0)), only_when=params.get("only_when") or (),
                        gp_inputs=params.get("gp_inputs") or DEFAULT_GP_INPUTS,
                        start_from=params.get("start_from"))
    context.report("calibrated; writing the run")
    return JobResult(outcome.record.to_dict(), _result_links(store, model, outcome.record.run_id))


def diagnose_job(store: GraphStore, params: dict, context: JobContext) -> JobResult:
    """``{"model", "measurements", "train", "test", "seed", "only_when", "start_from"}``:
    :func:`service.diagnosis.loop.diagnose`, its phases reported as progress (a cancel stops it at the next
    phase). One worker process: the job already runs beside the server's other work (or in a pool
    process, or on a Dask worker)."""
    from service.diagnosis.loop import diagnose  # the effect catalog machinery loads only when a diagnosis runs

    model = params["model"]
    data = context.measurements(params["measurements"])
    report = diagnose(store, model, data, train=parse_window(params["train"]), test=parse_window(params["test"]),
                      seed=int(params.get("seed", 0)), on_progress=context.report, workers=1,
                      only_when=params.get("only_when") or (), start_from=params.get("start_from"))
    links = _result_links(store, model, report.run_id)
    links["diagnosis_graph"] = store.run_graph(f"{report.run_id}-diagnosis").value
    return JobResult(report.to_dict(), links)


def _graph_triples(store: GraphStore, graph: ox.NamedNode) -> list[ox.Triple]:
    data = store.backend.dump(graph, ox.RdfFormat.N_TRIPLES)
    return parse_rdf(data, ox.RdfFormat.N_TRIPLES, str(graph)) if data else []


def effect_version_name(params: Mapping) -> str:
    """The model version an add-effect job names: ``params["version"]``, by default ``<model>+<effect>``."""
    return params.get("version") or f"{params['model']}+{params['effect']}"


def effect_version(store: GraphStore, params: dict) -> str:
    """The name of the model version an add-effect job writes (:func:`effect_version_name`), checked.

    :raises FileExistsError: that version exists with other effects (the same effect at another
        node, say): it is not overwritten — give ``version`` to keep both.
    """
    model, effect, target = params["model"], params["effect"], params["target"]
    version = store.check_name(effect_version_name(params))
    if store.has_model(version):
        library = SignatureLibrary.load()
        existing = recorded_effects(store, version, library)
        if set(existing) != {*recorded_effects(store, model, library), EffectRequest(effect, target)}:
            recorded = "; ".join(f"{r.effect} at {r.node}" for r in existing) or "no effect"
            raise FileExistsError(f"model {version} exists with {recorded}: it is not overwritten; "
                                  "give 'version' (a new model name) to keep both")
    return version


def add_effect_job(store: GraphStore, params: dict, context: JobContext) -> JobResult:
    """``{"model", "effect", "target"[, "version"]}``: a new model version (:func:`effect_version`):
    the model's triples plus the applied-effect triples (:mod:`service.model.effect_recording`), aligned and
    assembled in a scratch in-memory store (alignment reads the graph it derives from), then written
    with its ``inferred`` and ``assembly`` graphs. The model ``<model>`` itself is not changed; a
    version recorded with other effects is not overwritten."""
    model, effect, target = params["model"], params["effect"], params["target"]
    library = SignatureLibrary.load()
    signature = library.get(effect)
    if signature is None or signature.kind != "effect":
        known = ", ".join(sorted(s.id for s in library.values() if s.kind == "effect"))
        raise KeyError(f"no effect {effect!r}; the catalog has {known}")
    context.report(f"checking that {effect} applies at {target}")
    assemble(store, model, library=library, extra_effects=[EffectRequest(effect, target)])
    version = effect_version(store, params)
    triples = _graph_triples(store, store.model_graph(model)) + applied_effect_triples(signature, target)
    context.report(f"aligning and assembling {version}")
    scratch = GraphStore.embedded(None)
    scratch.load_model(version, ox.serialize(triples, format=ox.RdfFormat.N_TRIPLES), "nt", source_name=version)
    assembled = assemble(scratch, version, library=library)
    store.write_graph(store.model_graph(version), triples)
    store.write_graph(store.inferred_graph(version), _graph_triples(scratch, scratch.inferred_graph(version)))
    store.write_graph(store.assembly_graph(version), assembly_triples(assembled, version) + [
        ox.Triple(assembly_iri(version), GT.derivedFromModel, ox.Literal(model))])
    return JobResult(
        {"model": version, "base_model": model, "effect": effect, "target": target, "triples": len(triples),
         "components": len(assembled.components)},
        {"model": f"/models/{version}", "model_graph": store.model_graph(version).value},
    )
