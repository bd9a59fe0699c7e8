"""A :class:`service.store.SparqlBackend` on an external SPARQL 1.1 endpoint, over HTTP (``httpx``).

Protocols (W3C SPARQL 1.1 Protocol and Graph Store HTTP Protocol), with the Oxigraph server's URLs
(``oxigraph serve``: ``/query``, ``/update``, ``/store``) as :meth:`SparqlEndpointBackend.for_oxigraph_server`:

==================  ==========================================================================
``query``           ``POST query_url``, body ``application/sparql-query``; ``Accept:
                    application/sparql-results+json`` (SELECT, ASK) or ``application/n-triples``
                    (CONSTRUCT, DESCRIBE): the server picks by the query form, the reply's
                    ``Content-Type`` says which came back. ``default_graph`` becomes one
                    ``default-graph-uri`` URL parameter per graph.
``update``          ``POST update_url``, body ``application/sparql-update``.
``replace_graph``   ``POST store_url?graph=<staging>`` (N-Triples) into a fresh staging graph, then
                    one update ``MOVE SILENT GRAPH <staging> TO GRAPH <g>``
``load_graph``      parse locally with pyoxigraph, then as ``replace_graph``
``drop_graph``      ``DELETE store_url?graph=<g>`` (a 404 for an absent graph is success)
``dump``            ``GET store_url?graph=<g>`` with ``Accept`` = the format's media type
``graphs``          ``SELECT DISTINCT ?g WHERE { GRAPH ?g {} }``
``triple_count``    ``SELECT (COUNT(*) AS ?n) WHERE { GRAPH <g> { ?s ?p ?o } }``
==================  ==========================================================================

Without a ``store_url`` (an endpoint without the graph store protocol) ``replace_graph`` sends one
update ``DROP SILENT GRAPH <g> ; INSERT DATA { GRAPH <g> { … } }``
(:func:`service.store.insert_data_update`), ``drop_graph`` sends ``DROP SILENT GRAPH <g>`` and
``dump`` a ``CONSTRUCT`` that pyoxigraph serialises locally.

Atomicity. One SPARQL update request is one transaction in Oxigraph (the server runs it through
``Store::update``, "applied in a transactional manner: either the full operation succeeds or
nothing is written"), so after either ``MOVE`` or ``DROP … ; INSERT DATA`` a reader sees the old
graph or the new one, never a mix. ``replace_graph`` is *not* a graph store ``PUT``: the Oxigraph
server handles a PUT as ``clear_graph`` followed by a load, two transactions, between which a reader
can see the graph empty. The staging upload exists because the Oxigraph server refuses SPARQL
request bodies over 1 MiB (``MAX_SPARQL_BODY_SIZE``), while a graph store upload has no such limit;
the staging graph (``urn:graphtwin:staging:<uuid4>``) is visible in :meth:`graphs` only until the
``MOVE``, and is dropped if the ``MOVE`` fails. Without a ``store_url`` a graph is thus limited to
what the endpoint accepts in one update body.

Values (``substitutions``) are bound as in the embedded store (:func:`service.store.bind_values`):
a ``VALUES (?v …) { (…) }`` block inserted right after the opening brace of the query's outermost
``WHERE`` group (or ``ASK`` group), the terms serialised by pyoxigraph, never spliced from user text.

Dataset. Given ``default-graph-uri`` alone, the Oxigraph server leaves *no* named graph for
``GRAPH`` patterns, whereas the embedded store keeps every named graph available. To give both
backends one meaning, a query with a ``default_graph`` that mentions ``GRAPH`` also gets one
``named-graph-uri`` per graph in the store (one extra request, only then).

Errors: a request the endpoint rejects (HTTP 400, e.g. a SPARQL syntax error) raises
:class:`SparqlRequestError` (a ``ValueError``) with the server's text; an unreachable endpoint, a
refused token or a server failure raise :class:`SparqlEndpointError` (an ``OSError``), naming the URL.
RDF that does not parse raises :class:`service.store.ModelLoadError` before anything is sent.
"""

from __future__ import annotations

import re
import uuid
from collections.abc import Iterable, Mapping, Sequence

import httpx
import pyoxigraph as ox

from .store import bind_values, insert_data_update, parse_rdf

__all__ = ["SparqlEndpointBackend", "SparqlEndpointError", "SparqlRequestError", "STAGING_PREFIX"]

Term = ox.NamedNode | ox.BlankNode | ox.Literal
_RESULTS_JSON = "application/sparql-results+json"
_N_TRIPLES = "application/n-triples"
_GRAPH_KEYWORD = re.compile(r"\bGRAPH\b", re.IGNORECASE)
_MAX_SERVER_TEXT = 2000
#: Graphs named with this prefix hold an upload until it is moved into place.
STAGING_PREFIX = "urn:graphtwin:staging:"


class SparqlEndpointError(OSError):
    """The endpoint could not be reached, refused access, or failed; the message names the URL."""


class SparqlRequestError(ValueError):
    """The endpoint rejected a query or update as invalid (HTTP 400); the message carries its text."""


def _term(binding: Mapping) -> Term | ox.Triple:
    """One value of the SPARQL 1.1 Query Results JSON Format as a pyoxigraph term."""
    kind, value = binding["type"], binding["value"]
    if kind == "uri":
        return ox.NamedNode(value)
    if kind == "bnode":
        return ox.BlankNode(value)
    if kind in ("literal", "typed-literal"):
        if "xml:lang" in binding:
            return ox.Literal(value, language=binding["xml:lang"])
        if "datatype" in binding:
            return ox.Literal(value, datatype=ox.NamedNode(binding["datatype"]))
        return ox.Literal(value)
    if kind == "triple":
        return ox.Triple(_term(value["subject"]), _term(value["predicate"]), _term(value["object"]))
    raise ValueError(f"unknown term type {kind!r} in SPARQL JSON results")


class SparqlEndpointBackend:
    """graphtwin's :class:`~service.store.SparqlBackend` on a remote SPARQL 1.1 endpoint.

    :param query_url: the SPARQL query endpoint.
    :param update_url: the SPARQL update endpoint; None for a read-only endpoint (writes raise).
    :param store_url: the graph store protocol endpoint; None to do its work with SPARQL instead.
    :param token: sent as ``Authorization: Bearer <token>`` (an endpoint behind an auth proxy).
    :param timeout_s: per request (connect, read, write), seconds.
    """

    def __init__(self, query_url: str, update_url: str | None = None, store_url: str | None = None,
                 token: str | None = None, timeout_s: float = 30):
        self.query_url = query_url
        self.update_url = update_url
        self.store_url = store_url
        self.token = token
        self.timeout_s = timeout_s
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.client = httpx.Client(headers=headers, timeout=timeout_s)

    @classmethod
    def for_oxigraph_server(cls, url: str, *, token: str | None = None, timeout_s: float = 30) -> SparqlEndpointBackend:
        """An ``oxigraph serve`` at base ``url`` (e.g. ``http://oxigraph:7878``)."""
        base = url.rstrip("/")
        return cls(f"{base}/query", f"{base}/update", f"{base}/store", token=token, timeout_s=timeout_s)

    def close(self) -> None:
        self.client.close()

    def __enter__(self) -> SparqlEndpointBackend:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"SparqlEndpointBackend({self.query_url!r}, update_url={self.update_url!r}, store_url={self.store_url!r})"

    # ------------------------------------------------------------------ HTTP
    def _send(self, method: str, url: str, what: str, *, ok_missing: bool = False, **kwargs) -> httpx.Response | None:
        """One request; None for a 404 when ``ok_missing``; errors as described in the module doc."""
        try:
            response = self.client.request(method, url, **kwargs)
        except httpx.TimeoutException as exc:
            raise SparqlEndpointError(f"SPARQL endpoint {url}: {what} timed out after {self.timeout_s} s ({exc})") from None
        except httpx.HTTPError as exc:
            raise SparqlEndpointError(f"cannot reach SPARQL endpoint {url} ({what}): {exc}") from None
        if response.status_code == 404 and ok_missing:
            return None
        if response.is_success:
            return response
        text = response.text.strip()[:_MAX_SERVER_TEXT] or response.reason_phrase
        status = response.status_code
        if status == 400:
            raise SparqlRequestError(f"SPARQL endpoint {url} rejected the {what} (HTTP 400): {text}")
        if status in (401, 403):
            raise SparqlEndpointError(f"SPARQL endpoint {url} refused access to the {what} (HTTP {status}; check the token): {text}")
        raise SparqlEndpointError(f"SPARQL endpoint {url} failed on the {what} (HTTP {status}): {text}")

    def _require_update_url(self) -> str:
        if self.update_url is None:
            raise SparqlEndpointError(f"SPARQL endpoint {self.query_url} is read-only here: no update URL was given")
        return self.update_url

    # ------------------------------------------------------------------ SparqlBackend
    def query(self, sparql: str, *, substitutions: Mapping[str, Term] | None = None,
              default_graph: Sequence[ox.NamedNode] | None = None):
        """SELECT → ``list[dict[str, Term]]`` (unbound variables absent), ASK → ``bool``,
        CONSTRUCT/DESCRIBE → ``list[Triple]``.

        :raises SparqlRequestError: the endpoint rejected the query (syntax error: the server's text).
        :raises SparqlEndpointError: unreachable, refused, or failed.
        """
        text = bind_values(sparql, substitutions)
        params: list[tuple[str, str]] = []
        if default_graph is not None:
            params += [("default-graph-uri", g.value) for g in default_graph]
            if _GRAPH_KEYWORD.search(text):
                params += [("named-graph-uri", g.value) for g in self.graphs()]
        response = self._send(
            "POST", self.query_url, "query", params=params, content=text.encode("utf-8"),
            headers={"Content-Type": "application/sparql-query", "Accept": f"{_RESULTS_JSON}, {_N_TRIPLES};q=0.9"},
        )
        media_type = response.headers.get("content-type", "").split(";")[0].strip()
        if media_type == _N_TRIPLES:
            return [ox.Triple(q.subject, q.predicate, q.object)
                    for q in ox.parse(response.content, format=ox.RdfFormat.N_TRIPLES)]
        if media_type != _RESULTS_JSON:
            raise SparqlEndpointError(
                f"SPARQL endpoint {self.query_url} answered with {media_type or 'no content type'}, "
                f"expected {_RESULTS_JSON} or {_N_TRIPLES}"
            )
        body = response.json()
        if "boolean" in body:
            return bool(body["boolean"])
        return [{name: _term(value) for name, value in row.items()} for row in body["results"]["bindings"]]

    def update(self, sparql: str) -> None:
        """Run a SPARQL update: one request, one transaction on Oxigraph.

        :raises SparqlRequestError: the endpoint rejected the update (the server's text).
        """
        self._send("POST", self._require_update_url(), "update", content=sparql.encode("utf-8"),
                   headers={"Content-Type": "application/sparql-update"})

    def replace_graph(self, graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> None:
        """Replace ``graph`` by ``triples``, atomically for readers (see the module doc); empty drops it."""
        triples = list(triples)
        if not triples:
            self.drop_graph(graph)
            return
        if self.store_url is None:
            self.update(insert_data_update(graph, triples))
            return
        staging = ox.NamedNode(f"{STAGING_PREFIX}{uuid.uuid4().hex}")
        self._send("POST", self.store_url, "graph upload", params={"graph": staging.value},
                   content=ox.serialize(triples, format=ox.RdfFormat.N_TRIPLES),
                   headers={"Content-Type": _N_TRIPLES})
        try:
            self.update(f"MOVE SILENT GRAPH {staging} TO GRAPH {graph}")
        except (SparqlEndpointError, SparqlRequestError):
            self._send("DELETE", self.store_url, "staging graph deletion", params={"graph": staging.value}, ok_missing=True)
            raise

    def load_graph(self, graph: ox.NamedNode, data: bytes, format: ox.RdfFormat, *,
                   base_iri: str | None = None, source_name: str = "<data>") -> int:
        """Parse ``data`` here, then replace ``graph`` with it; returns the number of triples.

        :raises service.store.ModelLoadError: the data does not parse (source, line, column); nothing is sent.
        """
        triples = parse_rdf(data, format, source_name, base_iri)
        self.replace_graph(graph, triples)
        return len(triples)

    def drop_graph(self, graph: ox.NamedNode) -> None:
        """Remove ``graph``; dropping an absent graph is not an error."""
        if self.store_url is None:
            self.update(f"DROP SILENT GRAPH {graph}")
            return
        self._send("DELETE", self.store_url, "graph deletion", params={"graph": graph.value}, ok_missing=True)

    def graphs(self) -> list[ox.NamedNode]:
        """The named graphs holding at least one triple, sorted by IRI."""
        rows = self.query("SELECT DISTINCT ?g WHERE { GRAPH ?g { } }")
        return sorted((row["g"] for row in rows if isinstance(row.get("g"), ox.NamedNode)), key=lambda g: g.value)

    def dump(self, graph: ox.NamedNode, format: ox.RdfFormat) -> bytes:
        """``graph`` serialised in ``format``; ``b""`` for an absent graph."""
        if self.store_url is None:
            triples = self.query(f"CONSTRUCT {{ ?s ?p ?o }} WHERE {{ GRAPH {graph} {{ ?s ?p ?o }} }}")
            return ox.serialize(triples, format=format) or b""
        response = self._send("GET", self.store_url, "graph download", params={"graph": graph.value},
                              headers={"Accept": format.media_type}, ok_missing=True)
        return b"" if response is None else response.content

    def triple_count(self, graph: ox.NamedNode) -> int:
        rows = self.query(f"SELECT (COUNT(*) AS ?n) WHERE {{ GRAPH {graph} {{ ?s ?p ?o }} }}")
        return int(rows[0]["n"].value)
