"""Where a read query runs and what stops it (:class:`service.graph.query_reader.QueryReader`): an
external endpoint's HTTP timeout is the query time limit; the in-memory store's query is abandoned."""

import socket
import time

import pytest

from service.errors import QueryTimeoutError, StoreUnreachableError
from service.graph.backend import EmbeddedBackend
from service.graph.endpoint import SparqlEndpointBackend
from service.graph.query_answers import SparqlQuery
from service.graph.query_reader import QueryReader

ASK = SparqlQuery("ASK {}", "ASK", "application/sparql-results+json")


def test_an_endpoint_that_does_not_answer_is_given_up_at_the_query_time_limit():
    with socket.socket() as silent:  # accepts connections (the backlog), never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        url = f"http://127.0.0.1:{silent.getsockname()[1]}"
        backend = SparqlEndpointBackend.for_oxigraph_server(url, timeout_s=30, query_timeout_s=1)
        reader = QueryReader(backend, workers=1, timeout_s=1, max_rows=10)
        began = time.monotonic()
        with pytest.raises(StoreUnreachableError, match="no answer within 1 s"):
            reader.answer(ASK)
        assert time.monotonic() - began < 3
        assert reader.stoppable
        reader.close()
        backend.close()


def test_an_in_memory_query_past_the_limit_is_abandoned_and_says_so(monkeypatch):
    from service.graph import query_reader

    monkeypatch.setattr(query_reader, "backend_answer", lambda *args: time.sleep(3) or b"")
    reader = QueryReader(EmbeddedBackend(None), workers=1, timeout_s=0.5, max_rows=10)
    with pytest.raises(QueryTimeoutError, match="cannot be stopped"):
        reader.answer(ASK)
    assert not reader.stoppable
    reader.close()
