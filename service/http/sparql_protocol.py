"""The SPARQL 1.1 Protocol's reading side: a query's form and federation checked, the answer's media
type negotiated, the query run on a thread pool within a time limit, the answer serialised by
pyoxigraph (``docs/http.md``: limits, serialisation)."""

from __future__ import annotations

import asyncio
import json
import re
from dataclasses import dataclass

import pyoxigraph as ox
from fastapi import Response

from service.graph.backend import EmbeddedBackend, drain, query_bound
from service.graph.namespaces import PREFIXES
from service.graph.store import GraphStore
from service.http.deps import Service
from service.http.errors import ApiError

__all__ = ["SparqlQuery", "query_form", "calls_a_service", "fetching_keyword", "negotiate", "prepare_query",
           "answer_query", "UPDATE_KEYWORDS"]

_PROLOGUE = re.compile(r"\s*(?:#[^\n]*(?:\n|$)|BASE\s*<[^>]*>|PREFIX\s*[^\s:<>]*:\s*<[^>]*>"  # any PN_PREFIX
                       r"|VERSION\s*(?:\"[^\"\n]*\"|'[^'\n]*'))", re.IGNORECASE)  # SPARQL 1.2's VERSION "1.2"
_KEYWORD = re.compile(r"\s*([A-Za-z]+)")
UPDATE_KEYWORDS = frozenset({"INSERT", "DELETE", "LOAD", "CLEAR", "CREATE", "DROP", "COPY", "MOVE", "ADD", "WITH"})
RESULT_TYPES = {  # in the order a wildcard gets them; plain JSON, an alias, last
    "application/sparql-results+json": ox.QueryResultsFormat.JSON,
    "application/sparql-results+xml": ox.QueryResultsFormat.XML, "text/csv": ox.QueryResultsFormat.CSV,
    "text/tab-separated-values": ox.QueryResultsFormat.TSV, "application/json": ox.QueryResultsFormat.JSON,
}
GRAPH_TYPES = {
    "text/turtle": ox.RdfFormat.TURTLE, "application/n-triples": ox.RdfFormat.N_TRIPLES,
    "application/rdf+xml": ox.RdfFormat.RDF_XML, "application/ld+json": ox.RdfFormat.JSON_LD,
}


def query_form(sparql: str) -> str | None:
    """The first keyword after the prologue (comments, BASE, PREFIX, VERSION), upper case: ``SELECT``,
    ``CONSTRUCT``, ``ASK``, ``DESCRIBE``, or an update's ``INSERT``, ``DELETE``…; None when there is none."""
    position = 0
    while (match := _PROLOGUE.match(sparql, position)) and match.end() > position:
        position = match.end()
    keyword = _KEYWORD.match(sparql, position)
    return keyword.group(1).upper() if keyword else None


_TOKEN = re.compile(
    r'"""(?:[^"\\]|\\.|"(?!""))*"""' r"|'''(?:[^'\\]|\\.|'(?!''))*'''"  # long strings
    r'|"(?:[^"\\\n]|\\.)*"' r"|'(?:[^'\\\n]|\\.)*'"  # strings
    r'|<[^<>"{}|^`\\\s]*>|#[^\n]*'  # IRIs, comments
    r"""|[^\s"'<{}()#]+|\S"""  # words (keywords, prefixed names, variables), punctuation
)


def calls_a_service(sparql: str) -> bool:
    """Whether ``sparql`` has a ``SERVICE`` clause (a federated query: the engine would fetch another
    URL), read as tokens: the word in a string, an IRI, a comment or a name does not count."""
    return fetching_keyword(sparql) == "SERVICE"


def fetching_keyword(sparql: str) -> str | None:
    """``SERVICE`` or ``LOAD`` when ``sparql`` has one (the engine would fetch another URL on the
    caller's behalf), read as tokens as :func:`calls_a_service` does; None otherwise."""
    return next((word for token in _TOKEN.findall(sparql) if (word := token.upper()) in ("SERVICE", "LOAD")), None)


def negotiate(accept: str | None, offers: list[str]) -> str | None:
    """The offered media type the ``Accept`` header prefers (RFC 9110 §12.5.1: each offer takes the
    q-value of the most specific range that matches it, ``type/subtype`` over ``type/*`` over
    ``*/*``, so ``q=0`` refuses a type a wildcard would admit); ties go to the range named first,
    then to the first offer. The first offer when the header is absent; None when it accepts none."""
    if not accept or not accept.strip():
        return offers[0]
    ranges = []  # (media range, q, position in the header)
    for index, part in enumerate(accept.split(",")):
        media, *params = [p.strip() for p in part.split(";")]
        quality = 1.0
        for param in params:
            if param.startswith("q="):
                try:
                    quality = float(param[2:])
                except ValueError:
                    quality = 0.0
        if media:
            ranges.append((media.lower(), quality, index))

    def preference(offer: str) -> tuple[float, int]:
        matching = [(2 if media == offer else 1 if media != "*/*" else 0, quality, -index)
                    for media, quality, index in ranges
                    if media in (offer, "*/*") or media.endswith("/*") and offer.startswith(media[:-1])]
        if not matching:
            return 0.0, 0
        _, quality, position = max(matching)
        return quality, position

    best = max(offers, key=lambda offer: (preference(offer), -offers.index(offer)))
    return best if preference(best)[0] > 0 else None


class _ResultTooLarge(Exception):
    """An answer with more rows or triples than the service's limit."""


@dataclass(frozen=True)
class SparqlQuery:
    """A read query as it will run: its form, the media type of its answer, its dataset and bindings."""

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


def _execute(store: GraphStore, query: SparqlQuery, max_rows: int) -> bytes:
    """Run ``query`` and serialise its answer (on a query-pool thread)."""
    backend = store.backend
    if isinstance(backend, EmbeddedBackend):
        answer = _native_answer(backend.store, query, max_rows)
    else:
        default_graph = backend.graphs() if query.union_default_graph else query.default_graph
        result = backend.query(query.text, substitutions=query.substitutions, default_graph=default_graph)
        if isinstance(result, bool):
            answer = result
        elif query.form == "SELECT":
            variables = list(dict.fromkeys(name for row in result for name in row))
            answer = (variables, [tuple(row.get(v) for v in variables) for row in result])
        else:
            answer = list(result)
    if isinstance(answer, bool):
        return _boolean_bytes(answer, RESULT_TYPES[query.media_type])
    size = len(answer[1]) if isinstance(answer, tuple) else len(answer)
    if size > max_rows:
        raise _ResultTooLarge(f"the result has more than {max_rows} rows or triples (the service's limit): "
                              "narrow the query or add a LIMIT")
    if isinstance(answer, tuple):
        return _solutions_bytes(*answer, RESULT_TYPES[query.media_type])
    fmt = GRAPH_TYPES[query.media_type]
    return ox.serialize(answer, format=fmt, prefixes=PREFIXES if fmt == ox.RdfFormat.TURTLE else None)


def prepare_query(text: str | None, accept: str | None, default_graph_uris: list[str], union: bool) -> SparqlQuery:
    """A read query checked before it runs: present, no update, no ``SERVICE``, an answer type the
    ``Accept`` header admits, valid default graphs."""
    if not text or not text.strip():
        raise ApiError(400, "no query: give it as the query parameter or form field 'query', or as an "
                            "application/sparql-query body")
    form = query_form(text)
    if form in UPDATE_KEYWORDS:
        raise ApiError(403, "this endpoint only answers queries: send SPARQL Update to POST /sparql/update "
                            "with a bearer token")
    if calls_a_service(text):
        raise ApiError(403, "SERVICE (federated query) is refused here: the service would send requests to "
                            "other URLs on the caller's behalf; query the other endpoint directly")
    offers = list(GRAPH_TYPES) if form in ("CONSTRUCT", "DESCRIBE") else list(RESULT_TYPES)
    media = negotiate(accept, offers)
    if media is None:
        raise ApiError(406, f"cannot answer a {form or 'SPARQL'} query as {accept}; available: {', '.join(offers)}")
    try:
        graphs = [ox.NamedNode(uri) for uri in default_graph_uris] or None
    except ValueError as exc:
        raise ApiError(400, f"default-graph-uri: {exc}") from None
    return SparqlQuery(text, form or "", media, graphs, union)


async def answer_query(service: Service, query: SparqlQuery) -> Response:
    """Run ``query`` on the query pool within the service's time limit; the answer, or the error
    that says why there is none."""
    settings = service.settings
    future = service.query_pool.submit(_execute, service.store, query, settings.max_result_rows)
    try:
        body = await asyncio.wait_for(asyncio.wrap_future(future), timeout=settings.query_timeout_s)
    except TimeoutError:
        raise ApiError(503, f"the query did not finish within the time limit of {settings.query_timeout_s:g} s; "
                            "it may still be running in the store (it cannot be interrupted)") from None
    except (SyntaxError, ValueError) as exc:
        raise ApiError(400, f"SPARQL syntax error: {exc}") from None
    except _ResultTooLarge as exc:
        raise ApiError(422, str(exc)) from None
    except (OSError, RuntimeError) as exc:  # an unreachable or failing SPARQL endpoint (StoreUnavailableError)
        raise ApiError(503, f"the store did not answer: {exc}") from None
    return Response(body, media_type=query.media_type)
