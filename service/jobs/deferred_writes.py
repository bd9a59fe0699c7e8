"""A job's writes, kept until it ends and then committed in one transaction: a reader sees all of a
job's results or none, and a failed or cancelled job writes nothing."""

from __future__ import annotations

import pyoxigraph as ox

from service.graph.ntriples import triple_list
from service.graph.rdf_io import parse_rdf

__all__ = ["DeferredWrites"]


class DeferredWrites:
    """A :class:`~service.graph.backend.SparqlBackend` that reads ``backend`` and keeps whole-graph writes
    until :meth:`commit` writes them in one transaction (the backend's ``replace_graphs``: blank
    nodes shared between graphs stay shared).

    Reads go to ``backend`` unchanged: a graph written here is not seen before the commit.
    """

    def __init__(self, backend):
        self.backend = backend
        self._graphs: dict[ox.NamedNode, list[ox.Triple]] = {}

    def query(self, sparql, *, substitutions=None, default_graph=None):
        return self.backend.query(sparql, substitutions=substitutions, default_graph=default_graph)

    def update(self, sparql):
        raise TypeError("a job writes whole graphs (replace_graph, drop_graph); a SPARQL Update is not deferred")

    def replace_graph(self, graph, triples):
        self._graphs[graph] = list(triples)

    def replace_graphs(self, graphs):
        for graph, triples in graphs.items():
            self.replace_graph(graph, triple_list(triples))

    def load_graph(self, graph, data, format, *, base_iri=None, source_name="<data>"):
        triples = parse_rdf(data, format, source_name, base_iri)
        self.replace_graph(graph, triples)
        return len(triples)

    def drop_graph(self, graph):
        self._graphs[graph] = []

    def graphs(self):
        return self.backend.graphs()

    def dump(self, graph, format):
        return self.backend.dump(graph, format)

    def triple_count(self, graph):
        return self.backend.triple_count(graph)

    def written_graphs(self) -> list[ox.NamedNode]:
        """The graphs kept for the commit (written or dropped)."""
        return list(self._graphs)

    def shipped(self) -> tuple[bytes, list[str]]:
        """The kept graphs as one N-Quads document (blank nodes shared between graphs stay shared)
        and the IRIs of the graphs kept empty (drops): what shipped work sends back."""
        quads = [ox.Quad(t.subject, t.predicate, t.object, graph) for graph, triples in self._graphs.items() for t in triples]
        return ox.serialize(quads, format=ox.RdfFormat.N_QUADS), [g.value for g, t in self._graphs.items() if not t]

    def keep_shipped(self, nquads: bytes, dropped: list[str]) -> None:
        """Keep what :meth:`shipped` made elsewhere, as if the work had written it here."""
        graphs: dict[ox.NamedNode, list[ox.Triple]] = {ox.NamedNode(g): [] for g in dropped}
        for quad in ox.parse(nquads, format=ox.RdfFormat.N_QUADS):
            graphs.setdefault(quad.graph_name, []).append(quad.triple)
        self._graphs.update(graphs)

    def commit(self) -> None:
        """Write every kept graph in one transaction; nothing to do when nothing was written."""
        if not self._graphs:
            return
        self.backend.replace_graphs(self._graphs)
        self._graphs.clear()
