"""The contract between the job runner and a job's work: a kind (its request type and the function
that runs it), the context the work reports to, the result it returns."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from service.graph.store import GraphStore
from service.workflows.requests import JobRequest

__all__ = ["JobCancelled", "JobResult", "JobKind", "WorkContext", "public_message"]


class JobCancelled(Exception):
    """Raised inside a job's work when its cancellation was requested."""


@dataclass(frozen=True)
class JobResult:
    """What a job's work returns: a JSON-able ``result`` and ``links`` to what it wrote."""

    result: dict
    links: dict[str, str] = field(default_factory=dict)


class WorkContext(Protocol):
    """What a job's work is handed: progress, a cancel request, its measurement uploads."""

    job_id: str

    @property
    def cancel_requested(self) -> bool: ...

    def report(self, message: str) -> None:
        """Record a progress message; raises :class:`JobCancelled` when a cancel was requested."""

    def measurements(self, upload_id: str) -> Path:
        """The CSV of measurement upload ``upload_id``; :raises NotFoundError: no such upload."""


@dataclass(frozen=True)
class JobKind:
    """A kind of job: the ``request`` type its parameters are read into, and ``run(store, request,
    context) -> JobResult``, where ``store`` writes through deferred writes. Kinds that a process
    pool or Dask runs are pickled by reference: ``run`` is a module-level function."""

    request: type[JobRequest]
    run: Callable[[GraphStore, JobRequest, WorkContext], JobResult]


def public_message(message: str, request: JobRequest) -> str:
    """``message`` with the server's file path of the job's measurement upload (where the service or a
    worker keeps it) written as the upload's id, all a client knows of it."""
    for upload in request.uploads():
        message = re.sub(r"\S*" + re.escape(upload) + r"\.csv", f"upload {upload}", message)
    return message
