"""pyoxigraph's lazy results are unsendable: one dropped on another thread raises. A frame that
still holds one when it ends is enough for that to happen, because a sampling profiler (a Dask
worker's) keeps the frames it samples and releases them on its own thread. Here a profile hook
keeps every frame that returns, on the reading thread, and the main thread then releases them."""

import sys
import threading

import pyoxigraph as ox
from case_study import CASE_STUDY

from service.graph.store import GraphStore
from service.model.assembly import assemble

LAZY = (ox.QuerySolutions, ox.QueryTriples, ox.QueryBoolean)


def test_no_frame_still_holds_a_lazy_result_when_it_ends():
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    kept = []

    def keep(frame, event, arg):
        if event == "return":
            kept.append(frame)

    def work():
        sys.setprofile(keep)
        try:
            store.query("SELECT * WHERE { GRAPH ?g { ?s ?p ?o } } LIMIT 5")
            store.query("ASK { GRAPH ?g { ?s ?p ?o } }")
            store.query("CONSTRUCT { ?s ?p ?o } WHERE { GRAPH ?g { ?s ?p ?o } } LIMIT 5")
            assemble(store, "case")  # the signature matcher reads the store directly
        finally:
            sys.setprofile(None)

    reader = threading.Thread(target=work)
    reader.start()
    reader.join()
    assert len(kept) > 1000
    holding = sorted({f"{frame.f_code.co_filename.rsplit('/', 1)[-1]}:{frame.f_code.co_name}"
                      for frame in kept for value in frame.f_locals.values() if isinstance(value, LAZY)})
    kept.clear()  # released here, on the main thread
    assert holding == []
