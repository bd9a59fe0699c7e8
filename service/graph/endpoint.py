"""A :class:`service.graph.backend.SparqlBackend` on an external SPARQL 1.1 endpoint, over HTTP (``httpx``).

W3C SPARQL 1.1 Protocol and Graph Store HTTP Protocol, with the Oxigraph server's URLs (``oxigraph
serve``: ``/query``, ``/update``, ``/store``). Every write is one SPARQL update request, one
transaction on Oxigraph; values are bound and a default graph sees every named graph through
``GRAPH`` as in the embedded store. HTTP 400 raises :class:`~service.errors.StoreRequestError`, any
other failing status :class:`~service.errors.StoreUnavailableError`, no answer
:class:`~service.errors.StoreUnreachableError`. Requests, atomicity, datasets: ``docs/graph-store.md``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from urllib.parse import urlencode

import httpx
import pyoxigraph as ox

from service.errors import StoreRequestError, StoreUnavailableError, StoreUnreachableError
from service.graph.backend import Term, bind_values, insert_data_update
from service.graph.ntriples import GraphTriples
from service.graph.rdf_io import parse_rdf

__all__ = ["SparqlEndpointBackend"]

_RESULTS_JSON = "application/sparql-results+json"
_N_TRIPLES = "application/n-triples"
_GRAPH_KEYWORD = re.compile(r"\bGRAPH\b", re.IGNORECASE)
_MAX_SERVER_TEXT = 2000


def _term(binding: Mapping[str, str]) -> Term:
    """One value of the SPARQL 1.1 Query Results JSON Format (§3.2.2) as a pyoxigraph term."""
    kind, value = binding.get("type"), binding.get("value")
    if kind == "uri":
        return ox.NamedNode(value)
    if kind == "bnode":
        return ox.BlankNode(value)
    if kind == "literal":
        if "xml:lang" in binding:
            return ox.Literal(value, language=binding["xml:lang"])
        if "datatype" in binding:
            return ox.Literal(value, datatype=ox.NamedNode(binding["datatype"]))
        return ox.Literal(value)
    if kind == "triple" and isinstance(value, Mapping):  # RDF 1.2 / SPARQL 1.2 triple term
        return ox.Triple(*(_term(value[part]) for part in ("subject", "predicate", "object")))
    raise StoreUnavailableError(f"unsupported term {binding!r} in SPARQL JSON results (expected uri, bnode, literal or triple)")


class SparqlEndpointBackend:
    """graphtwin's :class:`~service.graph.backend.SparqlBackend` on a remote SPARQL 1.1 endpoint.

    :param query_url: the SPARQL query endpoint.
    :param update_url: the SPARQL update endpoint.
    :param store_url: the graph store protocol endpoint (used by :meth:`dump`).
    :param token: sent as ``Authorization: Bearer <token>`` (an endpoint behind an auth proxy).
    :param timeout_s: limit for each of connecting, sending and reading one request, seconds.
    :param query_timeout_s: the same for a query (the service's query time limit: the endpoint's
        HTTP timeout is what stops a query there); ``timeout_s`` when None.

    One ``httpx.Client`` (a connection pool, safe to share between threads) serves every request;
    :meth:`close` it, or use the backend as a context manager.
    """

    def __init__(self, query_url: str, update_url: str, store_url: str, token: str | None = None,
                 timeout_s: float = 30, query_timeout_s: float | None = None):
        self.query_url = query_url
        self.update_url = update_url
        self.store_url = store_url
        self.timeout_s = timeout_s
        self.query_timeout_s = query_timeout_s if query_timeout_s is not None else timeout_s
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.client = httpx.Client(headers=headers, timeout=timeout_s)

    @classmethod
    def for_oxigraph_server(cls, base_url: str, token: str | None = None, timeout_s: float = 30,
                            query_timeout_s: float | None = None) -> SparqlEndpointBackend:
        """An ``oxigraph serve`` at ``base_url`` (e.g. ``http://oxigraph:7878``)."""
        base = base_url.rstrip("/")
        return cls(f"{base}/query", f"{base}/update", f"{base}/store", token=token, timeout_s=timeout_s,
                   query_timeout_s=query_timeout_s)

    def close(self) -> None:
        self.client.close()

    def __enter__(self) -> SparqlEndpointBackend:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"SparqlEndpointBackend({self.query_url!r}, {self.update_url!r}, {self.store_url!r}, "
                f"timeout_s={self.timeout_s!r})")

    # ------------------------------------------------------------------ HTTP
    def _send(self, method: str, url: str, what: str, *, missing_ok: bool = False, **kwargs) -> httpx.Response | None:
        """One request; None for a 404 when ``missing_ok``.

        :raises StoreRequestError: HTTP 400 (the server's text).
        :raises StoreUnavailableError: any other failing status (the URL and the status).
        :raises StoreUnreachableError: no connection, or no answer within the timeout (the URL).
        """
        timeout_s = self.query_timeout_s if what == "query" else self.timeout_s
        try:
            response = self.client.request(method, url, timeout=timeout_s, **kwargs)
        except httpx.TimeoutException as exc:
            raise StoreUnreachableError(
                f"SPARQL endpoint {url}: the {what} got no answer within {timeout_s:g} s ({exc})") from None
        except httpx.TransportError as exc:
            raise StoreUnreachableError(f"cannot reach SPARQL endpoint {url} ({what}): {exc}") from None
        if response.status_code == 404 and missing_ok:
            return None
        if response.is_success:
            return response
        status = response.status_code
        text = response.text.strip()[:_MAX_SERVER_TEXT] or response.reason_phrase
        if status == 400:
            raise StoreRequestError(f"SPARQL endpoint {url} rejected the {what} (HTTP 400): {text}")
        raise StoreUnavailableError(f"SPARQL endpoint {url} failed on the {what} (HTTP {status}): {text}")

    # ------------------------------------------------------------------ SparqlBackend
    def query(self, sparql: str, *, substitutions: Mapping[str, Term] | None = None,
              default_graph: Sequence[ox.NamedNode] | None = None):
        """SELECT → ``list[dict[str, Term]]`` (unbound variables absent), ASK → ``bool``,
        CONSTRUCT/DESCRIBE → ``list[Triple]``, all read completely.

        :param substitutions: variable name → term, bound by :func:`service.graph.backend.bind_values`.
        :param default_graph: the named graphs whose union is the default graph.
        :raises StoreRequestError: the endpoint rejected the query (a syntax error: the server's text).
        :raises StoreUnavailableError: the endpoint failed; :class:`StoreUnreachableError`: no answer.
        """
        text = bind_values(sparql, substitutions)
        if default_graph is None:
            content_type, body = "application/sparql-query", text
        else:
            form = [("query", text)] + [("default-graph-uri", g.value) for g in default_graph]
            if _GRAPH_KEYWORD.search(text):
                form += [("named-graph-uri", g.value) for g in self.graphs()]
            content_type, body = "application/x-www-form-urlencoded", urlencode(form)
        response = self._send("POST", self.query_url, "query", content=body.encode("utf-8"), headers={
            "Content-Type": content_type, "Accept": f"{_RESULTS_JSON}, {_N_TRIPLES};q=0.9"})
        media_type = response.headers.get("content-type", "").split(";")[0].strip()
        if media_type == _N_TRIPLES:
            return [ox.Triple(q.subject, q.predicate, q.object)
                    for q in ox.parse(response.content, format=ox.RdfFormat.N_TRIPLES)]
        if media_type != _RESULTS_JSON:
            raise StoreUnavailableError(f"SPARQL endpoint {self.query_url} answered the query with "
                                        f"{media_type or 'no content type'}, expected {_RESULTS_JSON} or {_N_TRIPLES}")
        try:
            results = response.json()
        except ValueError as exc:
            raise StoreUnavailableError(f"SPARQL endpoint {self.query_url} sent invalid JSON results: {exc}") from None
        if "boolean" in results:
            return bool(results["boolean"])
        return [{name: _term(value) for name, value in row.items()} for row in results["results"]["bindings"]]

    def update(self, sparql: str) -> None:
        """Run a SPARQL update request: one request, one transaction on Oxigraph.

        :raises StoreRequestError: the endpoint rejected the update (the server's text).
        """
        self._send("POST", self.update_url, "update", content=sparql.encode("utf-8"),
                   headers={"Content-Type": "application/sparql-update"})

    def replace_graph(self, graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> None:
        """Replace ``graph`` by ``triples`` (none: remove it) in one update request, atomically for
        readers (``docs/graph-store.md``, External endpoint)."""
        self.replace_graphs({graph: triples})

    def replace_graphs(self, graphs: Mapping[ox.NamedNode, GraphTriples]) -> None:
        """Replace several graphs (:data:`service.graph.ntriples.GraphTriples`; none: remove it) in one update
        request."""
        self.update(insert_data_update(graphs))

    def load_graph(self, graph: ox.NamedNode, data: bytes, format: ox.RdfFormat, *,
                   base_iri: str | None = None, source_name: str = "<data>") -> int:
        """Parse ``data`` here, then replace ``graph`` with it; returns the number of triples.

        :raises service.errors.ModelLoadError: the data does not parse (source, line, column); nothing is sent.
        """
        triples = parse_rdf(data, format, source_name, base_iri)
        self.replace_graph(graph, triples)
        return len(triples)

    def drop_graph(self, graph: ox.NamedNode) -> None:
        """Remove ``graph``; dropping an absent graph is not an error."""
        self.update(f"DROP SILENT GRAPH {graph}")

    def graphs(self) -> list[ox.NamedNode]:
        """The named graphs in the store, sorted by IRI."""
        rows = self.query("SELECT DISTINCT ?g WHERE { GRAPH ?g { } }")
        return sorted((row["g"] for row in rows), key=lambda g: g.value)

    def dump(self, graph: ox.NamedNode, format: ox.RdfFormat) -> bytes:
        """``graph`` serialised by the endpoint in ``format``; ``b""`` for an absent graph."""
        response = self._send("GET", self.store_url, "graph download", missing_ok=True,
                              params={"graph": graph.value}, headers={"Accept": format.media_type})
        return b"" if response is None else response.content

    def triple_count(self, graph: ox.NamedNode) -> int:
        """Triples in ``graph`` (0 when absent)."""
        rows = self.query(f"SELECT (COUNT(*) AS ?n) WHERE {{ GRAPH {graph} {{ ?s ?p ?o }} }}")
        return int(rows[0]["n"].value)
