"""A read query's answer as the bytes a client gets: run on a pyoxigraph store (in this process or in a
read worker, :mod:`service.graph.read_workers`) or on any :class:`~service.graph.backend.SparqlBackend`,
at most ``max_rows`` rows or triples, serialised by pyoxigraph in the media type asked for.

Imported by the read workers: it imports pyoxigraph and the graph floor's light modules only.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import pyoxigraph as ox

from service.errors import ResultTooLargeError
from service.graph.backend import EmbeddedBackend, SparqlBackend, drain, query_bound
from service.graph.namespaces import PREFIXES

__all__ = ["SparqlQuery", "RESULT_TYPES", "GRAPH_TYPES", "store_answer", "backend_answer"]

RESULT_TYPES = {  # in the order a wildcard gets them; plain JSON, an alias, last
    "application/sparql-results+json": ox.QueryResultsFormat.JSON,
    "application/sparql-results+xml": ox.QueryResultsFormat.XML, "text/csv": ox.QueryResultsFormat.CSV,
    "text/tab-separated-values": ox.QueryResultsFormat.TSV, "application/json": ox.QueryResultsFormat.JSON,
}
GRAPH_TYPES = {
    "text/turtle": ox.RdfFormat.TURTLE, "application/n-triples": ox.RdfFormat.N_TRIPLES,
    "application/rdf+xml": ox.RdfFormat.RDF_XML, "application/ld+json": ox.RdfFormat.JSON_LD,
}


@dataclass(frozen=True)
class SparqlQuery:
    """A read query as it will run: its form, the media type of its answer, its dataset and bindings
    (picklable: it is sent to a read worker as it is)."""

    text: str
    form: str
    media_type: str
    default_graph: list[ox.NamedNode] | None = None
    union_default_graph: bool = False
    substitutions: dict[str, ox.NamedNode | ox.Literal] | None = None  # a named query's parameters


def _tsv_term(term) -> str:
    """A term as SPARQL TSV writes it (RDF 1.2: a triple term as ``<<( s p o )>>``; unbound: empty)."""
    if term is None:
        return ""
    if isinstance(term, ox.Triple):
        return f"<<( {_tsv_term(term.subject)} {_tsv_term(term.predicate)} {_tsv_term(term.object)} )>>"
    return str(term)


def _solutions_bytes(variables: list[str], rows: list[tuple], fmt: ox.QueryResultsFormat) -> bytes:
    """Rows of terms → ``fmt``, through pyoxigraph's TSV parser and its serialiser."""
    lines = ["\t".join(f"?{v}" for v in variables)]
    lines += ["\t".join(map(_tsv_term, row)) for row in rows]
    return ox.parse_query_results("\n".join(lines) + "\n", ox.QueryResultsFormat.TSV).serialize(format=fmt)


def _boolean_bytes(value: bool, fmt: ox.QueryResultsFormat) -> bytes:
    parsed = ox.parse_query_results(json.dumps({"head": {}, "boolean": value}), ox.QueryResultsFormat.JSON)
    return parsed.serialize(format=fmt)


def _native_answer(store: ox.Store, query: SparqlQuery, max_rows: int):
    """Run on the pyoxigraph store; the lazy result lives and dies in this call, on this thread
    (pyoxigraph results are unsendable: dropping one on another thread raises)."""
    kwargs = {"use_default_graph_as_union": True} if query.union_default_graph else (
        {"default_graph": query.default_graph} if query.default_graph else {})
    result = query_bound(store, query.text, query.substitutions, **kwargs)
    try:
        if isinstance(result, ox.QueryBoolean):
            return bool(result)
        if isinstance(result, ox.QuerySolutions):
            variables = [v.value for v in result.variables]
            return variables, drain(result, tuple, limit=max_rows + 1)
        return drain(result, limit=max_rows + 1)
    finally:
        del result  # see service.graph.backend.drain


def _serialised(answer, query: SparqlQuery, max_rows: int) -> bytes:
    if isinstance(answer, bool):
        return _boolean_bytes(answer, RESULT_TYPES[query.media_type])
    size = len(answer[1]) if isinstance(answer, tuple) else len(answer)
    if size > max_rows:
        raise ResultTooLargeError(f"the result has more than {max_rows} rows or triples (the service's limit): "
                                  "narrow the query or add a LIMIT")
    if isinstance(answer, tuple):
        return _solutions_bytes(*answer, RESULT_TYPES[query.media_type])
    fmt = GRAPH_TYPES[query.media_type]
    return ox.serialize(answer, format=fmt, prefixes=PREFIXES if fmt == ox.RdfFormat.TURTLE else None)


def store_answer(store: ox.Store, query: SparqlQuery, max_rows: int) -> bytes:
    """``query`` run on a pyoxigraph store, serialised.

    :raises SyntaxError: the query is not SPARQL; :class:`~service.errors.ResultTooLargeError`: over ``max_rows``.
    """
    return _serialised(_native_answer(store, query, max_rows), query, max_rows)


def backend_answer(backend: SparqlBackend, query: SparqlQuery, max_rows: int) -> bytes:
    """``query`` run on ``backend`` (pyoxigraph's own results when it is embedded), serialised."""
    if isinstance(backend, EmbeddedBackend):
        return store_answer(backend.store, query, max_rows)
    default_graph = backend.graphs() if query.union_default_graph else query.default_graph
    result = backend.query(query.text, substitutions=query.substitutions, default_graph=default_graph)
    if isinstance(result, bool):
        answer = result
    elif query.form == "SELECT":
        variables = list(dict.fromkeys(name for row in result for name in row))
        answer = (variables, [tuple(row.get(v) for v in variables) for row in result])
    else:
        answer = list(result)
    return _serialised(answer, query, max_rows)
