"""Work shipped away from the server (a local process pool, a Dask cluster): the embedded on-disk
store is opened by one process only, so the job's thread ships the graphs the job reads and its
measurement upload (:class:`ShippedJob`), the work runs on a scratch in-memory store holding them
(:func:`run_shipped_job`), and the graphs it wrote travel back as N-Quads for the job's one commit."""

from __future__ import annotations

import json
import pickle
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pyoxigraph as ox

from service.errors import GraphtwinError, NotFoundError
from service.graph.store import GraphStore
from service.jobs.deferred_writes import DeferredWrites
from service.jobs.records import now
from service.jobs.work import JobCancelled, JobResult, WorkContext
from service.workflows.requests import JobRequest

__all__ = ["ShippedJob", "ShippedContext", "ShippedWorkError", "run_shipped_job", "ship_job", "read_progress"]


class ShippedWorkError(Exception):
    """Shipped work raised something other than a user's error (a bug): its type and message as
    text, since not every exception survives the way back from a pool process or a Dask worker."""


@dataclass(frozen=True)
class ShippedJob:
    """Everything a job needs away from the server (picklable): its ``request``, the graphs it reads
    (``dataset``, N-Quads), the bytes of its measurement uploads by upload id, and where its progress
    messages go as they are made (``progress_path``: a file the server reads while the job runs, one
    JSON line a message; None where the worker shares no files with the server: a Dask cluster)."""

    job_id: str
    request: JobRequest
    dataset: bytes
    measurements: dict[str, bytes] = field(default_factory=dict)
    progress_path: str | None = None


class ShippedContext:
    """The work context of shipped work: progress messages are kept (they travel back with the
    result) and written to the job's progress file as they come, measurements are the shipped bytes
    written to ``folder``."""

    cancel_requested = False

    def __init__(self, job: ShippedJob, folder: Path):
        self.job_id, self._job, self._folder = job.job_id, job, Path(folder)
        self.messages: list[dict] = []

    def report(self, message: str) -> None:
        entry = {"time": now(), "message": message}
        self.messages.append(entry)
        if self._job.progress_path is not None:
            with open(self._job.progress_path, "a", encoding="utf-8") as progress:
                progress.write(json.dumps(entry) + "\n")

    def measurements(self, upload_id: str) -> Path:
        if upload_id not in self._job.measurements:
            raise NotFoundError(f"no measurement upload {upload_id!r}")
        path = self._folder / f"{upload_id}.csv"
        if not path.is_file():
            path.write_bytes(self._job.measurements[upload_id])
        return path


def read_progress(path: Path, offset: int) -> tuple[list[dict], int]:
    """The whole progress lines written to ``path`` after byte ``offset``, and the offset after them."""
    try:
        with open(path, "rb") as progress:
            progress.seek(offset)
            text = progress.read()
    except FileNotFoundError:
        return [], offset
    complete = text[: text.rfind(b"\n") + 1]
    return [json.loads(line) for line in complete.splitlines()], offset + len(complete)


def run_shipped_job(run: Callable[[GraphStore, JobRequest, WorkContext], JobResult],
                    job: ShippedJob) -> tuple[JobResult, bytes, list[str], list[dict]]:
    """Run ``run`` on a scratch in-memory store holding ``job.dataset``: in a pool process or on a
    Dask worker. Returns the result, the graphs written (:meth:`DeferredWrites.shipped`) and the
    progress messages. Its scratch folder lies beside its progress file, where there is one (the
    service removes that folder at its shutdown, or at its next start after a kill). A user's error
    travels back as it is, or as a :class:`GraphtwinError` with its message where its type would not
    unpickle; anything else as :class:`ShippedWorkError`."""
    scratch = GraphStore.embedded(None)
    scratch.backend.store.load(job.dataset, format=ox.RdfFormat.N_QUADS)
    writes = DeferredWrites(scratch.backend)
    near_progress = None if job.progress_path is None else Path(job.progress_path).parent
    with tempfile.TemporaryDirectory(prefix="graphtwin-job-", dir=near_progress) as folder:
        context = ShippedContext(job, Path(folder))
        try:
            outcome = run(GraphStore(writes), job.request, context)
        except (JobCancelled, FileNotFoundError):
            raise
        except GraphtwinError as exc:
            if not _travels(exc):
                raise GraphtwinError(str(exc)) from None
            raise
        except Exception as exc:
            raise ShippedWorkError(f"{type(exc).__name__}: {exc}") from None
    nquads, dropped = writes.shipped()
    return outcome, nquads, dropped, context.messages


def _travels(exc: BaseException) -> bool:
    """Whether ``exc`` unpickles as it was: its type and its message."""
    try:
        copy = pickle.loads(pickle.dumps(exc))
        return type(copy) is type(exc) and str(copy) == str(exc)
    except Exception:  # noqa: BLE001 (any failure to round-trip means: send it as text)
        return False


def ship_job(store: GraphStore, job_id: str, request: JobRequest,
             locate_measurements: Callable[[str], Path] | None, progress_path: Path | None = None) -> ShippedJob:
    """What :func:`run_shipped_job` needs for a job on ``store``: the graphs its request reads
    (:meth:`~service.workflows.requests.JobRequest.graphs_read`) and the bytes of its uploads.

    :raises NotFoundError: an upload does not exist.
    """
    quads = [ox.Quad(t.subject, t.predicate, t.object, graph)
             for graph in dict.fromkeys(request.graphs_read(store)) for t in store.graph_triples(graph)]
    files = {}
    for upload in request.uploads():
        if locate_measurements is None:
            raise NotFoundError(f"no measurement upload {upload!r}: this runner keeps no uploads")
        files[upload] = Path(locate_measurements(upload)).read_bytes()
    return ShippedJob(job_id, request, ox.serialize(quads, format=ox.RdfFormat.N_QUADS), files,
                      str(progress_path) if progress_path is not None else None)
