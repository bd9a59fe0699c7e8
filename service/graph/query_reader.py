"""Read queries of a store within a time limit, each where it can be stopped when it runs past it.

* the embedded store on disk: on :class:`~service.graph.read_workers.ReadWorkers` (killed and
  replaced past the limit);
* an external SPARQL endpoint: its HTTP timeout is the limit (``query_timeout_s`` of
  :class:`~service.graph.endpoint.SparqlEndpointBackend`), on threads;
* the in-memory store (tests): on threads; a pyoxigraph query cannot be stopped, so one past the
  limit is abandoned and runs to its end.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path

from service.errors import QueryTimeoutError
from service.graph.backend import EmbeddedBackend, SparqlBackend
from service.graph.endpoint import SparqlEndpointBackend
from service.graph.query_answers import SparqlQuery, backend_answer
from service.graph.read_workers import ReadWorkers

__all__ = ["QueryReader", "snapshots_folder"]


def snapshots_folder(store_path: Path) -> Path:
    """Where the read checkpoints of the store at ``store_path`` go: beside it (the same file system,
    so a checkpoint is hard links), ``<store>.read-snapshots``."""
    return store_path.with_name(f"{store_path.name}.read-snapshots")


class QueryReader:
    """Answers read queries of ``backend`` with at most ``workers`` at once, each within ``timeout_s``
    and ``max_rows`` rows or triples (serialised bytes, :mod:`service.graph.query_answers`)."""

    def __init__(self, backend: SparqlBackend, *, workers: int, timeout_s: float, max_rows: int) -> None:
        self.backend, self.timeout_s, self.max_rows = backend, timeout_s, max_rows
        self._processes = self._threads = None
        if isinstance(backend, EmbeddedBackend) and backend.path is not None:
            self._processes = ReadWorkers(backend, workers, snapshots_folder(backend.path))
        else:
            self._threads = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="graphtwin-sparql")

    @property
    def stoppable(self) -> bool:
        """Whether a query past the limit is stopped (not left running)."""
        return self._processes is not None or isinstance(self.backend, SparqlEndpointBackend)

    def answer(self, query: SparqlQuery) -> bytes:
        """The serialised answer of ``query`` (blocks the calling thread).

        :raises QueryTimeoutError: past the time limit (the message says whether it was stopped).
        :raises SyntaxError, ResultTooLargeError, StoreError: as the store raises them."""
        if self._processes is not None:
            return self._processes.answer(query, self.max_rows, self.timeout_s)
        future = self._threads.submit(backend_answer, self.backend, query, self.max_rows)
        try:
            return future.result(timeout=self.timeout_s if not self.stoppable else None)
        except FutureTimeout:
            raise QueryTimeoutError(f"the query did not finish within the time limit of {self.timeout_s:g} s; it is "
                                    "still running (a query of the in-memory store cannot be stopped)") from None

    def close(self) -> None:
        """Stop the workers (a running query is not waited for)."""
        if self._processes is not None:
            self._processes.close()
        else:
            self._threads.shutdown(wait=False, cancel_futures=True)
