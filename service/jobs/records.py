"""Job records: kind, request, status, progress messages, result and links of each job, as a JSON
file ``<jobs dir>/<id>.json`` rewritten atomically on every change (a crash leaves the previous
version, never half of one). Status moves ``queued → running → succeeded | failed | cancelled``; a
record a stopped process left ``queued`` or ``running`` is marked ``interrupted`` at start-up."""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from enum import StrEnum
from pathlib import Path

import numpy as np

__all__ = ["JobStatus", "ACTIVE", "JobRecord", "JobRecords", "json_safe", "now"]

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


def now() -> str:
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
    created: str = field(default_factory=now)
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
                record.status, record.finished = JobStatus.INTERRUPTED, now()
                self.save(record)
                marked.append(record.id)
        return marked
