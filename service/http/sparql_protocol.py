"""The SPARQL 1.1 Protocol's reading side: a query's form and federation checked, the answer's media
type negotiated, the reads admitted within the service's limits (429 over them) and run within its
time limit (:class:`~service.graph.query_reader.QueryReader`; ``docs/http.md``: limits, serialisation)."""

from __future__ import annotations

import re

import pyoxigraph as ox
from fastapi import Request, Response
from starlette.concurrency import run_in_threadpool

from service.errors import QueryTimeoutError, ResultTooLargeError, StoreError
from service.graph.query_answers import GRAPH_TYPES, RESULT_TYPES, SparqlQuery
from service.graph.rdf_io import sparql_syntax_message
from service.http.deps import ReadAdmission, Service
from service.http.errors import ApiError

__all__ = ["SparqlQuery", "query_form", "calls_a_service", "fetching_keyword", "negotiate", "prepare_query",
           "answer_query", "UPDATE_KEYWORDS"]

_PROLOGUE = re.compile(r"\s*(?:#[^\n]*(?:\n|$)|BASE\s*<[^>]*>|PREFIX\s*[^\s:<>]*:\s*<[^>]*>"  # any PN_PREFIX
                       r"|VERSION\s*(?:\"[^\"\n]*\"|'[^'\n]*'))", re.IGNORECASE)  # SPARQL 1.2's VERSION "1.2"
_KEYWORD = re.compile(r"\s*([A-Za-z]+)")
UPDATE_KEYWORDS = frozenset({"INSERT", "DELETE", "LOAD", "CLEAR", "CREATE", "DROP", "COPY", "MOVE", "ADD", "WITH"})


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


async def answer_query(service: Service, query: SparqlQuery, request: Request) -> Response:
    """Run ``query`` within the service's limits (:class:`ReadAdmission`; the time limit: a query
    past it is stopped where the store allows, :class:`~service.graph.query_reader.QueryReader`); the
    answer, or the error that says why there is none."""
    with service.read_admission.admitted(ReadAdmission.clients(request)):
        try:
            body = await run_in_threadpool(service.reads.answer, query)
        except QueryTimeoutError as exc:
            raise ApiError(503, str(exc)) from None
        except ResultTooLargeError as exc:
            raise ApiError(422, str(exc)) from None
        except StoreError:
            raise
        except SyntaxError as exc:
            raise ApiError(400, sparql_syntax_message(query.text, exc)) from None
        except ValueError as exc:
            raise ApiError(400, f"SPARQL syntax error: {exc}") from None
        except (OSError, RuntimeError) as exc:  # the store failed on the query
            raise ApiError(503, f"the store did not answer: {exc}") from None
    return Response(body, media_type=query.media_type)
