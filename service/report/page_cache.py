"""Report pages kept once built: a small least-recently-used cache keyed by what a page is built from.

A page costs ~1.5 s of CPU (the model simulated again, six figures drawn); it changes only when what
it reads does. The key holds the run id and the state of the page's sources: a digest of the run
graph and of its diagnosis graph (a run or diagnosis written again or deleted), a digest of the
store's graph names (a later run of the model in the error history, a model dropped), and the run's
data file's modification time (or why it cannot be found). More: ``docs/report.md``, *Cached pages*.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path

import pyoxigraph as ox

from service.calibration.triples import run_iri
from service.graph.store import GraphStore
from service.report.page import report_html
from service.report.stored_run import DIAGNOSIS_SUFFIX

__all__ = ["ReportPageCache", "page_state"]

def _digest(data: bytes) -> str:
    return hashlib.blake2b(data, digest_size=16).hexdigest()


def page_state(store: GraphStore, run_id: str, locate_data: Callable[[str], Path] | None) -> tuple[str, ...]:
    """What the page of ``run_id`` is built from, as a key: run graph, diagnosis graph, the store's
    graph names, the data file (its path and modification time in ns, or why it is missing).

    :raises ValueError: ``run_id`` cannot name a run.
    """
    base = run_id.removesuffix(DIAGNOSIS_SUFFIX)
    run_graph, diagnosis_graph = store.run_graph(base), store.run_graph(base + DIAGNOSIS_SUFFIX)
    graphs = _digest("\n".join(g.value for g in store.backend.graphs()).encode("utf-8"))
    run = _digest(store.backend.dump(run_graph, ox.RdfFormat.N_TRIPLES))
    diagnosis = _digest(store.backend.dump(diagnosis_graph, ox.RdfFormat.N_TRIPLES))
    data = "no data locator"
    if locate_data is not None:
        rows = store.run_named_query("run-data-sources", g=run_graph, run=run_iri(base))
        try:
            path = locate_data(rows[0]["source"].value) if rows else None
            data = f"{path}@{path.stat().st_mtime_ns}" if path is not None else "no data source"
        except (LookupError, OSError, ValueError) as exc:
            data = f"not found: {exc}"
    return run_id, run, diagnosis, graphs, data


class ReportPageCache:
    """The last ``max_pages`` report pages built (the least recently used dropped first), each kept
    under :func:`page_state`: a page whose sources changed is built again. Thread-safe (pages are
    built on worker threads); two requests for the same new page may both build it."""

    def __init__(self, max_pages: int = 16) -> None:
        self.max_pages = max_pages
        self._pages: OrderedDict[tuple[str, ...], str] = OrderedDict()
        self._lock = threading.Lock()

    def page(self, store: GraphStore, run_id: str, *, locate_data: Callable[[str], Path] | None = None) -> str:
        """The page of ``run_id`` (:func:`~service.report.page.report_html`), built only when its
        sources changed since it was last built.

        :raises NotFoundError: no such run (nothing is cached then).
        """
        try:
            key = page_state(store, run_id, locate_data)
        except ValueError:  # not a run id: report_html says so
            return report_html(store, run_id, locate_data=locate_data)
        with self._lock:
            if key in self._pages:
                self._pages.move_to_end(key)
                return self._pages[key]
        page = report_html(store, run_id, locate_data=locate_data)
        with self._lock:
            self._pages[key] = page
            self._pages.move_to_end(key)
            while len(self._pages) > self.max_pages:
                self._pages.popitem(last=False)
        return page
