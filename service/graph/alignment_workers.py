"""Alignment worker processes: a large model's independent parts aligned side by side without
sharing Python's lock.

A worker is a fresh interpreter, ``python -m service.graph.alignment_workers`` (neither forked nor
started by :mod:`multiprocessing`), started when the alignment starts. The protocol is pickles over
the worker's stdin and a private copy of its stdout (the worker's own ``print`` goes to stderr): the
alignment context once per :meth:`AlignmentWorkers.map`, then a part's N-Triples text per request,
answered with what :func:`service.graph.alignment_derivation._aligned_part` returns, or with the
worker's traceback. Why processes, and why started this way: ``docs/alignment.md``.
"""

from __future__ import annotations

import gc
import os
import pickle
import subprocess
import sys
import threading
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import TracebackType
from typing import Any

from service.graph.alignment_derivation import _aligned_part

__all__ = ["AlignmentWorkerError", "AlignmentWorkers"]

_PACKAGE_PARENT = str(Path(__file__).resolve().parents[2])  # the folder holding the service package


class AlignmentWorkerError(RuntimeError):
    """An alignment worker process failed: its traceback, or how it exited."""


class AlignmentWorkers:
    """``n`` worker processes, started on creation; use as a context manager (they end on exit).

    :raises OSError: when a worker process cannot be started (the ones started are ended).

    :meth:`map` sends each worker the context, then parts one at a time to whichever worker is free
    (one thread per worker waits on its pipe, without Python's lock)."""

    def __init__(self, n: int) -> None:
        # the worker imports this package from where this process found it, whatever its own path
        path = os.pathsep.join(p for p in (_PACKAGE_PARENT, os.environ.get("PYTHONPATH")) if p)
        self._processes: list[subprocess.Popen] = []
        try:
            for _ in range(max(n, 1)):
                self._processes.append(subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                                                        stdout=subprocess.PIPE, env={**os.environ, "PYTHONPATH": path}))
        except OSError:  # no interpreter to start (an embedded Python, a process limit): none left running
            self.close(kill=True)
            raise

    def map(self, context: Any, texts: Iterable[bytes]) -> list[tuple[bytes, list[bytes]]]:
        """:func:`~service.graph.alignment_derivation._aligned_part` of each text with ``context``, in order.

        :raises AlignmentWorkerError: with the first failing worker's traceback or exit status."""
        numbered, lock, results, failed = enumerate(texts), threading.Lock(), {}, threading.Event()

        def serve(process: subprocess.Popen) -> None:
            try:
                pickle.dump(("context", context), process.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                while not failed.is_set():
                    with lock:
                        k, text = next(numbered, (None, None))
                    if k is None:
                        return
                    pickle.dump(("part", text), process.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                    process.stdin.flush()
                    error, answer = pickle.load(process.stdout)
                    if error:
                        raise AlignmentWorkerError(f"alignment worker {process.pid} failed:\n{answer}")
                    results[k] = answer
            except (BrokenPipeError, EOFError):
                failed.set()
                raise AlignmentWorkerError(f"alignment worker {process.pid} exited with status {process.wait()}") from None
            except BaseException:
                failed.set()
                raise

        with ThreadPoolExecutor(len(self._processes)) as pool:
            for future in [pool.submit(serve, process) for process in self._processes]:
                future.result()
        return [results[k] for k in range(len(results))]

    def close(self, *, kill: bool = False) -> None:
        """End the workers: end of input, then a wait (a worker still busy after it is killed; all of
        them at once with ``kill``)."""
        if kill:
            for process in self._processes:
                process.kill()
        for process in self._processes:
            try:
                process.stdin.close()
            except OSError:  # a worker that died has closed its end
                pass
        for process in self._processes:
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            process.stdout.close()

    def __enter__(self) -> AlignmentWorkers:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None) -> None:
        self.close(kill=error is not None)


def _serve() -> None:
    """A worker's loop until the end of its input: a request is ``("context", context)`` (for the
    parts after it) or ``("part", N-Triples text)``."""
    import traceback

    answers = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # a stray print must not break the protocol
    requests = sys.stdin.buffer
    gc.disable()  # the process only aligns (see service.runtime)
    context = None
    while True:
        try:
            kind, value = pickle.load(requests)
        except EOFError:
            return
        if kind == "context":
            context = value
            continue
        try:
            answer = (False, _aligned_part(value, context))
        except Exception:  # noqa: BLE001 (sent to the parent, which raises it)
            answer = (True, traceback.format_exc())
        pickle.dump(answer, answers, protocol=pickle.HIGHEST_PROTOCOL)
        answers.flush()


if __name__ == "__main__":
    _serve()
