"""Long-running work of the HTTP service as jobs, run by :class:`JobRunner`.

Each job runs on a thread of its own (``max_workers`` at a time); its work runs there, in a local
process pool or on a Dask cluster (:mod:`service.jobs.executors`, shipped: :mod:`service.jobs.shipping`).
A job reads the store as it is and writes through :class:`~service.jobs.deferred_writes.DeferredWrites`,
committed in one update before its status says ``succeeded``; a failed or cancelled job writes
nothing, and a job whose model changed while it ran writes nothing either. A queued job is cancelled
at once; a running one is flagged: its work stops at its next progress message (or its shipped work
is dropped) and its results are discarded. Design: ``docs/http.md``.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path

from service.calibration.run import model_version
from service.errors import ConflictError, GraphtwinError, InputError, NotFoundError
from service.graph.store import GraphStore
from service.jobs.deferred_writes import DeferredWrites
from service.jobs.records import ACTIVE, JobRecord, JobRecords, JobStatus, json_safe, now
from service.jobs.shipping import ShippedWorkError, read_progress, run_shipped_job, ship_job
from service.jobs.work import JobCancelled, JobKind, JobResult, public_message
from service.workflows.requests import JobRequest, ModelRequest

__all__ = ["JobRunner", "JobContext", "JobStateError"]

log = logging.getLogger("graphtwin.jobs")


class JobStateError(ConflictError):
    """The operation does not apply to the job in its current state (the message says why)."""


class JobContext:
    """Handed to a job's work on the runner's thread: report progress, learn about a cancel request,
    find its measurements."""

    def __init__(self, runner: JobRunner, job_id: str):
        self._runner, self.job_id = runner, job_id

    def measurements(self, upload_id: str) -> Path:
        """The CSV of measurement upload ``upload_id``.

        :raises NotFoundError: no such upload.
        """
        if self._runner.locate_measurements is None:
            raise NotFoundError(f"no measurement upload {upload_id!r}: this runner keeps no uploads")
        return self._runner.locate_measurements(upload_id)

    @property
    def cancel_requested(self) -> bool:
        return self._runner.get(self.job_id).cancel_requested

    def report(self, message: str) -> None:
        """Record a progress message; raises :class:`JobCancelled` when a cancel was requested."""
        self._runner._progress(self.job_id, message)
        if self.cancel_requested:
            raise JobCancelled()


class JobRunner:
    """Runs jobs of the registered ``kinds`` on ``store``, ``max_workers`` at a time (module docstring:
    threads, results, cancellation). Records persist through ``records``."""

    def __init__(self, store: GraphStore, records: JobRecords, kinds: Mapping[str, JobKind], *, max_workers: int = 1,
                 locate_measurements: Callable[[str], Path] | None = None, executor=None):
        """:param locate_measurements: upload id → CSV path (:meth:`JobContext.measurements`).
        :param executor: None (work on the job's thread), a :class:`ProcessJobExecutor` or a
            :class:`DaskJobExecutor` (see :func:`job_executor`); :meth:`shutdown` shuts it down."""
        self.store, self.records, self.kinds = store, records, dict(kinds)
        self.locate_measurements, self.executor = locate_measurements, executor
        self._lock = threading.RLock()
        self._jobs = {r.id: r for r in records.all()}
        self._queue: queue.SimpleQueue[str | None] = queue.SimpleQueue()
        self._stopping = False
        # daemon threads: a service told to stop does not wait for a job's work to end (its record says
        # interrupted, its pool process is terminated), as a non-daemon pool thread would make it
        self._threads = [threading.Thread(target=self._take_jobs, name=f"graphtwin-job-{i}", daemon=True)
                         for i in range(max_workers)]
        for thread in self._threads:
            thread.start()

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
    def submit(self, kind: str, request: JobRequest, *, resubmitted_from: str | None = None) -> JobRecord:
        """Queue a job; returns its record at once (``params``: the request as JSON).

        :raises NotFoundError: an unknown kind; :raises InputError: a request of another kind's type.
        """
        if kind not in self.kinds:
            raise NotFoundError(f"unknown job kind {kind!r}; known: {', '.join(sorted(self.kinds))}")
        if not isinstance(request, self.kinds[kind].request):
            raise InputError(f"a {kind} job takes a {self.kinds[kind].request.__name__}, not a {type(request).__name__}")
        record = JobRecord(id=uuid.uuid4().hex, kind=kind, params=json_safe(request.model_dump(mode="json")),
                           resubmitted_from=resubmitted_from)
        with self._lock:
            if self._stopping:
                raise JobStateError("the service is stopping: resubmit the job when it runs again")
            self._jobs[record.id] = record
            self.records.save(record)
            self._queue.put(record.id)
        return self.get(record.id)

    def resubmit(self, job_id: str) -> JobRecord:
        """A new job with the kind and parameters of a finished one.

        :raises NotFoundError: an unknown job; :raises JobStateError: the job is still queued or running.
        """
        old = self.get(job_id)
        if old is None:
            raise NotFoundError(f"no job {job_id!r}")
        if old.status in ACTIVE:
            raise JobStateError(f"job {job_id} is {old.status}: cancel it or wait for it before resubmitting")
        return self.submit(old.kind, self.request_of(old), resubmitted_from=job_id)

    def cancel(self, job_id: str) -> JobRecord:
        """Cancel a queued job at once, flag a running one (module docstring).

        :raises NotFoundError: an unknown job; :raises JobStateError: the job has already ended.
        """
        with self._lock:
            record = self._jobs.get(job_id)
            if record is None:
                raise NotFoundError(f"no job {job_id!r}")
            if record.status not in ACTIVE:
                raise JobStateError(f"job {job_id} has already ended ({record.status})")
            if record.status == JobStatus.QUEUED:  # a job thread takes it and finds it ended
                record.status, record.finished = JobStatus.CANCELLED, now()
                record.progress.append({"time": now(), "message": "cancelled before it started"})
            else:
                record.cancel_requested = True
                record.progress.append({"time": now(), "message": "cancel requested: the results will be discarded"})
            self.records.save(record)
        return self.get(job_id)

    def shutdown(self, wait: bool = True, *, interrupt: bool = False) -> None:
        """Stop taking jobs: queued ones are marked ``interrupted``. Running ones end first (``wait``:
        this call waits for them), or with ``interrupt`` are marked ``interrupted`` at once, their
        shipped work dropped (a pool process terminated) and their results, should their thread still
        finish, discarded: what a service told to stop does."""
        with self._lock:
            self._stopping = True
            for record in self._jobs.values():
                if record.status == JobStatus.QUEUED or (interrupt and record.status == JobStatus.RUNNING):
                    when = "before the job started" if record.status == JobStatus.QUEUED else "while the job ran"
                    record.status, record.finished = JobStatus.INTERRUPTED, now()
                    record.error, record.cancel_requested = f"the service stopped {when}; resubmit it", True
                    self.records.save(record)
        for _ in self._threads:
            self._queue.put(None)
        if interrupt or wait:
            if self.executor is not None:
                self.executor.shutdown()
        if wait and not interrupt:
            for thread in self._threads:
                thread.join()

    # ------------------------------------------------------------------ internals
    def request_of(self, record: JobRecord) -> JobRequest:
        """The typed request of ``record`` (its params as they were submitted)."""
        return self.kinds[record.kind].request.model_validate(record.params)

    def _model_state(self, request: JobRequest) -> tuple[str | None, frozenset[str]]:
        """What a job's results rest on: the version of the model it reads (None without one) and the
        model graphs the store holds."""
        model = request.model if isinstance(request, ModelRequest) else None
        version = model_version(self.store, model) if model is not None and self.store.has_model(model) else None
        prefix = self.store.model_graph("x").value[:-1]
        return version, frozenset(g.value for g in self.store.backend.graphs() if g.value.startswith(prefix))

    def _conflict(self, request: JobRequest, before: tuple[str | None, frozenset[str]], writes: DeferredWrites) -> str | None:
        """Why the job's results must not be written (called under the lock, before the commit): its
        model changed while it ran (another load replaced it), or a model graph it would create was
        created meanwhile (two add-effect jobs naming the same version); None when they may be."""
        version, models = self._model_state(request)
        if version != before[0]:
            return (f"the model {request.model!r} changed while the job ran (version {before[0]} → {version}): its "
                    "results would describe a model the store no longer holds; resubmit the job")
        created = sorted(g.value for g in writes.written_graphs() if g.value in models - before[1])
        if created:
            return (f"{', '.join(created)} was written by another job while this one ran: not overwritten; resubmit "
                    "with another version name")
        return None

    def _take_jobs(self) -> None:
        """A job thread: runs queued jobs until :meth:`shutdown`."""
        while (job_id := self._queue.get()) is not None:
            self._run(job_id)

    def _record_progress(self, job_id: str, messages: list[dict]) -> None:
        """Progress entries (``{"time", "message"}``) made by shipped work, recorded and saved."""
        if not messages:
            return
        with self._lock:
            record = self._jobs[job_id]
            record.progress.extend(messages)
            self.records.save(record)

    def _progress(self, job_id: str, message: str) -> None:
        with self._lock:
            record = self._jobs[job_id]
            record.progress.append({"time": now(), "message": message})
            self.records.save(record)

    def _finish(self, job_id: str, status: str, *, error: str | None = None, message: str | None = None) -> None:
        """End a job's record; a job the service's stop interrupted stays interrupted."""
        with self._lock:
            record = self._jobs[job_id]
            if record.status == JobStatus.INTERRUPTED:
                return
            record.status, record.finished, record.error = status, now(), error
            if message:
                record.progress.append({"time": record.finished, "message": message})
            self.records.save(record)

    def _run_shipped(self, job_id: str, kind: str, request: JobRequest, writes: DeferredWrites) -> JobResult:
        """Run the job's work on ``self.executor``; wait for it, dropping it when a cancel is requested."""
        progress_path = self.executor.progress_path(job_id)
        future = self.executor.submit(run_shipped_job, self.kinds[kind].run,
                                      ship_job(self.store, job_id, request, self.locate_measurements, progress_path))
        self._progress(job_id, f"sent to {self.executor.name}")
        seen, offset = 0, 0
        try:
            # poll done() rather than result(timeout=...): distributed's result() can lose a result that
            # arrives as its timeout expires (an UnboundLocalError inside distributed.utils.sync)
            while not future.done():
                if self.get(job_id).cancel_requested:
                    self.executor.cancel(future)
                    raise JobCancelled()
                if progress_path is not None:  # the work's progress as it goes, not only at its end
                    messages, offset = read_progress(progress_path, offset)
                    if messages:
                        self._record_progress(job_id, messages)
                        seen += len(messages)
                time.sleep(0.2)
            outcome, nquads, dropped, messages = future.result()
        finally:
            if progress_path is not None:
                progress_path.unlink(missing_ok=True)
        self._record_progress(job_id, messages[seen:])
        writes.keep_shipped(nquads, dropped)
        return outcome

    def _run(self, job_id: str) -> None:
        with self._lock:
            record = self._jobs[job_id]
            if record.status != JobStatus.QUEUED:
                return
            record.status, record.started = JobStatus.RUNNING, now()
            record.progress.append({"time": record.started, "message": "started"})
            self.records.save(record)
            kind, request = record.kind, self.request_of(record)
        writes = DeferredWrites(self.store.backend)
        try:
            before = self._model_state(request)
            if self.executor is None:
                outcome = self.kinds[kind].run(GraphStore(writes), request, JobContext(self, job_id))
            else:
                outcome = self._run_shipped(job_id, kind, request, writes)
        except JobCancelled:
            self._finish(job_id, JobStatus.CANCELLED, message="cancelled; nothing was written")
            return
        except (GraphtwinError, FileNotFoundError) as exc:
            self._finish(job_id, JobStatus.FAILED, error=public_message(str(exc), request),
                         message="failed; nothing was written")
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
            try:
                conflict = self._conflict(request, before, writes)
                if conflict:
                    self._finish(job_id, JobStatus.FAILED, error=conflict, message="failed; nothing was written")
                    return
                writes.commit()
            except Exception as exc:  # the store failed after the work was done (an endpoint gone)
                log.exception("job %s (%s) could not write its results", job_id, kind)
                self._finish(job_id, JobStatus.FAILED, error=f"writing the results failed: {exc}",
                             message="failed; nothing was written")
                return
            record.result, record.links = json_safe(outcome.result), dict(outcome.links)
            self._finish(job_id, JobStatus.SUCCEEDED, message="results written to the store")
