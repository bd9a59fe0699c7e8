"""Read queries of an on-disk store on worker processes that can be stopped: a query past its time
limit is ended with its process (pyoxigraph 0.5 cannot cancel a query), and a fresh worker takes its
place.

A worker is a fresh interpreter, ``python -m service.graph.read_workers``, started with the pool and
importing pyoxigraph and :mod:`service.graph.query_answers` only. It reads a checkpoint of the store
(:meth:`~service.graph.backend.EmbeddedBackend.checkpoint`; opening the live store read-only while
this process writes it is undefined behaviour in pyoxigraph 0.5), made when a read comes after a write
and removed once no worker holds it. The protocol is pickles over the worker's stdin and a private
copy of its stdout: ``(checkpoint folder, query, max rows)`` answered by ``(True, bytes)`` or
``(False, exception)``. Design and figures: ``docs/graph-store.md``, Read snapshots.
"""

from __future__ import annotations

import os
import pickle
import queue
import select
import shutil
import subprocess
import sys
import threading
from collections import Counter
from pathlib import Path

from service.errors import QueryTimeoutError, StoreUnavailableError
from service.graph.backend import EmbeddedBackend
from service.graph.query_answers import SparqlQuery, store_answer

__all__ = ["ReadWorkers"]

_PACKAGE_PARENT = str(Path(__file__).resolve().parents[2])  # the folder holding the service package


class _Worker:
    """One worker process and the checkpoint it has open (None before its first query)."""

    def __init__(self) -> None:
        path = os.pathsep.join(p for p in (_PACKAGE_PARENT, os.environ.get("PYTHONPATH")) if p)
        self.process = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        env={**os.environ, "PYTHONPATH": path})
        self.checkpoint: Path | None = None

    def ask(self, checkpoint: Path, query: SparqlQuery, max_rows: int, timeout_s: float) -> tuple[bool, object] | None:
        """Send a query, wait for its answer at most ``timeout_s``; None when none came in time.

        :raises EOFError, BrokenPipeError: the worker is gone."""
        pickle.dump((str(checkpoint), query, max_rows), self.process.stdin, protocol=pickle.HIGHEST_PROTOCOL)
        self.process.stdin.flush()
        readable, _, _ = select.select([self.process.stdout], [], [], timeout_s)
        if not readable:
            return None
        return pickle.load(self.process.stdout)

    def kill(self) -> int:
        """End the process now; its exit status."""
        self.process.kill()
        status = self.process.wait()
        for pipe in (self.process.stdin, self.process.stdout):
            try:
                pipe.close()
            except OSError:  # a worker that died has closed its end
                pass
        return status


class ReadWorkers:
    """``n`` worker processes reading checkpoints of ``backend`` (on disk) kept under ``snapshots``
    (emptied now: a stopped service's leftovers; on the store's file system, so that a checkpoint is
    hard links). :meth:`answer` is called from any number of threads; at most ``n`` run at once, the
    others wait for a free worker."""

    def __init__(self, backend: EmbeddedBackend, n: int, snapshots: Path) -> None:
        self.backend = backend
        self.snapshots = snapshots
        shutil.rmtree(snapshots, ignore_errors=True)
        snapshots.mkdir(parents=True)
        self._lock = threading.Lock()  # the checkpoints and their holders
        self._newest: tuple[int, Path] | None = None  # generation, folder
        self._made = 0
        self._holders: Counter[Path] = Counter()
        self._idle: queue.SimpleQueue[_Worker] = queue.SimpleQueue()
        self._workers: set[_Worker] = set()
        self._closed = False
        for _ in range(max(n, 1)):
            self._add_worker()

    @property
    def pids(self) -> set[int]:
        """The worker processes' ids."""
        with self._lock:
            return {worker.process.pid for worker in self._workers}

    def _add_worker(self) -> None:
        worker = _Worker()
        with self._lock:
            self._workers.add(worker)
        self._idle.put(worker)

    def _fresh_checkpoint(self) -> Path:
        """The newest checkpoint, made now when a write came after it. Under ``_lock``."""
        if self._newest is None or self._newest[0] != self.backend.generation:
            self._made += 1
            folder = self.snapshots / f"checkpoint-{self._made}"
            old = self._newest
            self._newest = (self.backend.checkpoint(folder), folder)
            if old is not None:
                self._release(old[1], 0)
        return self._newest[1]

    def _release(self, folder: Path | None, holders: int = 1) -> None:
        """``holders`` fewer hold ``folder``; removed when none does and it is not the newest. Under ``_lock``."""
        if folder is None:
            return
        self._holders[folder] -= holders
        if self._holders[folder] <= 0 and (self._newest is None or self._newest[1] != folder):
            del self._holders[folder]
            shutil.rmtree(folder, ignore_errors=True)

    def answer(self, query: SparqlQuery, max_rows: int, timeout_s: float) -> bytes:
        """``query`` answered on a worker, from a checkpoint holding every write made before this
        call; a worker still running it after ``timeout_s`` is killed and replaced.

        :raises QueryTimeoutError: no free worker within ``timeout_s``, or the query was stopped.
        :raises SyntaxError, ResultTooLargeError, OSError: as :func:`~service.graph.query_answers.store_answer`.
        :raises StoreUnavailableError: the worker ended of itself (out of memory)."""
        try:
            worker = self._idle.get(timeout=timeout_s)
        except queue.Empty:
            raise QueryTimeoutError(f"no read worker became free within the time limit of {timeout_s:g} s") from None
        try:
            with self._lock:
                checkpoint = self._fresh_checkpoint()
                self._holders[checkpoint] += 1
        except BaseException:  # no checkpoint (a full disk): the worker stays free
            self._idle.put(worker)
            raise
        try:
            reply = worker.ask(checkpoint, query, max_rows, timeout_s)
        except (EOFError, BrokenPipeError, pickle.UnpicklingError):
            reply = False
        with self._lock:
            self._release(worker.checkpoint)
            worker.checkpoint = checkpoint
            if not reply:
                self._release(checkpoint)
                self._workers.discard(worker)
        if not reply:
            status = worker.kill()
            if not self._closed:
                self._add_worker()
            if reply is None:
                raise QueryTimeoutError(f"the query was stopped after {timeout_s:g} s (the service's time limit)")
            raise StoreUnavailableError(f"the read worker ended with status {status} during the query")
        self._idle.put(worker)
        ok, value = reply
        if not ok:
            raise value
        return value

    def close(self) -> None:
        """Kill every worker (a query still running is not waited for) and remove the checkpoints."""
        self._closed = True
        with self._lock:
            workers, self._workers = list(self._workers), set()
        for worker in workers:
            worker.kill()
        shutil.rmtree(self.snapshots, ignore_errors=True)


def _serve() -> None:
    """A worker's loop until the end of its input: each request is answered from its checkpoint,
    opened read-only when it differs from the last one."""
    import pyoxigraph as ox

    from service.runtime import exit_with_parent

    exit_with_parent()  # a killed service cannot end a worker busy with a long query
    answers = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # a stray print must not break the protocol
    requests = sys.stdin.buffer
    opened, store = None, None
    while True:
        try:
            checkpoint, query, max_rows = pickle.load(requests)
        except EOFError:
            return
        try:
            if checkpoint != opened:
                store, opened = None, None
                store, opened = ox.Store.read_only(checkpoint), checkpoint
            answer = (True, store_answer(store, query, max_rows))
        except Exception as exc:  # noqa: BLE001 (sent to the parent, which raises it)
            answer = (False, exc if _picklable(exc) else RuntimeError(f"{type(exc).__name__}: {exc}"))
        pickle.dump(answer, answers, protocol=pickle.HIGHEST_PROTOCOL)
        answers.flush()


def _picklable(exc: Exception) -> bool:
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001 (any failure means: send it as text)
        return False
    return True


if __name__ == "__main__":
    _serve()
