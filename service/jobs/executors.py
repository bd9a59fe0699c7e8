"""Where a job's work runs: on the job's thread (``threads``), in a local process pool
(``processes``, the service's default) or on a Dask distributed cluster (``dask://HOST:PORT``)."""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from pathlib import Path
from urllib.parse import urlsplit

from service.errors import InputError
from service.jobs.shipping import ShippedJob
from service.runtime import exit_with_parent
from service.settings import check_executor

__all__ = ["ProcessJobExecutor", "DaskJobExecutor", "job_executor", "WORK_FOLDER_PREFIX"]

log = logging.getLogger("graphtwin.jobs")


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
        self._work_folder = _work_folder()

    def progress_path(self, job_id: str) -> Path:
        """Where a job's process writes its progress as it goes (the server reads it meanwhile); its
        scratch folder goes beside it (:func:`service.jobs.shipping.run_shipped_job`)."""
        return self._work_folder / f"{job_id}.jsonl"

    @staticmethod
    def _new_pool() -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=1, mp_context=get_context("spawn"), initializer=_start_job_worker)

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
        shutil.rmtree(self._work_folder, ignore_errors=True)


#: The prefix of a service's work folder in the temporary directory, followed by its process id.
WORK_FOLDER_PREFIX = "graphtwin-jobs-"


def _work_folder() -> Path:
    """A new folder for this process's jobs (progress files, scratch folders), named with its process
    id. Those of processes no longer running (a service killed before its shutdown) are removed first."""
    for folder in Path(tempfile.gettempdir()).glob(f"{WORK_FOLDER_PREFIX}*"):
        pid = folder.name[len(WORK_FOLDER_PREFIX):].split("-")[0]
        if pid.isdigit() and not _running(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
    return Path(tempfile.mkdtemp(prefix=f"{WORK_FOLDER_PREFIX}{os.getpid()}-"))


def _running(pid: int) -> bool:
    """Whether a process ``pid`` exists (another user's included)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def _start_job_worker() -> None:
    """Pool initializer of a job's process: a process group of its own, so a stop sent to the service's
    group (Ctrl-C in its terminal, ``kill -- -PGID``) reaches the service alone, which then marks the
    running job interrupted and stops this process (it had died first, and the job was recorded as
    failed); and it ends with the service (:func:`~service.runtime.exit_with_parent`)."""
    os.setpgrp()
    exit_with_parent()


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
            raise InputError("the Dask executor needs the distributed package: pip install 'graphtwin[dask]'") from None
        if isinstance(address, Client):
            self.client, self._own_client = address, False
        else:
            try:
                self.client, self._own_client = Client(address, timeout=connect_timeout_s, set_as_default=False), True
            except OSError as exc:
                raise InputError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        self.name = f"the Dask cluster at {self.client.scheduler.address}"

    def progress_path(self, job_id: str) -> None:
        """None: a Dask worker shares no files with the server, its progress comes with the result."""
        return None

    def submit(self, function, run, job: ShippedJob):
        return self.client.submit(function, run, job, pure=False, key=f"graphtwin-job-{job.job_id}")

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
