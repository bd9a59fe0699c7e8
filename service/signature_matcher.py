"""Match a signature in a graph: run its compiled query, then keep only *nearest* traverse matches.

Nearness (the paper's "follow the predicate until an instance of the class is found"), exactly:
``s P+ o`` such that some path from ``s`` to ``o`` along ``P`` has no intermediate node that is an
instance of the searched-for end's allowed classes (see :mod:`service.sparql_compiler`). It is checked with a breadth-first search from ``s`` over
the predicate's edges that does not expand through blocking nodes; the edges and the blocking nodes
are read once per (predicate, classes) and each search result is cached per start node, so the cost
is linear in the part of the graph the matches touch. Searches never expand a node twice, so loops
(return air mixed back into the supply) terminate and give the right answer: a sensor on a loop
finds the equipment right before it, not everything on the loop.

A failed *optional* traverse unbinds its OPTIONAL block (the block binds all together or not at
all); a failed required traverse drops the row. Results are fully consumed, sorted and de-duplicated.
"""

from __future__ import annotations

from collections import defaultdict, deque
from collections.abc import Sequence

import pyoxigraph as ox

from .signature import Signature
from .sparql_compiler import CompiledQuery, Traversal, compile_signature

__all__ = ["Match", "match_signature", "missing_class_report"]


class Match(dict):
    """Pattern node id → bound IRI string / literal lexical form / None; ``literals`` keeps the
    bound :class:`pyoxigraph.Literal` of literal nodes (datatype, language)."""

    def __init__(self, *args, literals: dict[str, ox.Literal] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.literals = literals or {}


def _query(store, sparql: str, default_graph):
    if isinstance(store, ox.Store):
        kwargs = {"default_graph": list(default_graph)} if default_graph is not None else {}
        result = store.query(sparql, **kwargs)
        if isinstance(result, ox.QuerySolutions):
            names = [v.value for v in result.variables]
            return [{n: s[n] for n in names if s[n] is not None} for s in result]
        return result
    return store.query(sparql, default_graph=default_graph)


def _value(term) -> str:
    if isinstance(term, ox.BlankNode):
        return f"_:{term.value}"
    return term.value


class _NearestChecker:
    """Caches the edges of each predicate, the instances of each class set and each search."""

    def __init__(self, store, default_graph):
        self.store, self.default_graph = store, default_graph
        self._edges: dict[str, dict[str, set[str]]] = {}
        self._instances: dict[tuple[str, ...], set[str]] = {}
        self._reach: dict[tuple[str, tuple[str, ...], str], set[str]] = {}

    def edges(self, predicate: str) -> dict[str, set[str]]:
        if predicate not in self._edges:
            adjacency: dict[str, set[str]] = defaultdict(set)
            rows = _query(self.store, f"SELECT ?a ?b WHERE {{ ?a {ox.NamedNode(predicate)} ?b }}", self.default_graph)
            for row in rows:
                adjacency[_value(row["a"])].add(_value(row["b"]))
            self._edges[predicate] = adjacency
        return self._edges[predicate]

    def instances(self, classes: tuple[str, ...]) -> set[str]:
        if classes not in self._instances:
            values = " ".join(str(ox.NamedNode(c)) for c in classes)
            rows = _query(
                self.store,
                "SELECT DISTINCT ?x WHERE { VALUES ?c { %s } ?x <http://www.w3.org/1999/02/22-rdf-syntax-ns#type>/"
                "<http://www.w3.org/2000/01/rdf-schema#subClassOf>* ?c }" % values,
                self.default_graph,
            )
            self._instances[classes] = {_value(r["x"]) for r in rows}
        return self._instances[classes]

    def reachable(self, traversal: Traversal, start: str) -> set[str]:
        """Nodes reachable from ``start`` whose path passes no blocking node in between."""
        key = (traversal.predicate, traversal.blocking_classes, start)
        if key not in self._reach:
            adjacency = self.edges(traversal.predicate)
            blocking = self.instances(traversal.blocking_classes)
            seen: set[str] = set()
            queue = deque([start])
            while queue:
                node = queue.popleft()
                for nxt in adjacency.get(node, ()):
                    if nxt in seen:
                        continue
                    seen.add(nxt)
                    if nxt not in blocking:
                        queue.append(nxt)
            self._reach[key] = seen
        return self._reach[key]

    def nearest(self, traversal: Traversal, subject: str, obj: str) -> bool:
        return obj in self.reachable(traversal, subject)


def match_signature(
    store, signature: Signature, *, default_graph: Sequence[ox.NamedNode] | None = None,
    compiled: CompiledQuery | None = None,
) -> list[Match]:
    """Every match of ``signature`` (see the module docstring), sorted.

    :param store: a :class:`~service.store.GraphStore`, a backend, or a bare pyoxigraph ``Store``.
    :param default_graph: the graphs the pattern is matched in (model + inferred + ontologies).
    """
    compiled = compiled or compile_signature(signature)
    rows = _query(store, compiled.text, default_graph)
    checker = _NearestChecker(store, default_graph)
    node_ids = [n for n in signature.nodes]
    seen: set[tuple] = set()
    matches: list[Match] = []
    for row in rows:
        values: dict[str, str | None] = {}
        literals: dict[str, ox.Literal] = {}
        for node_id in node_ids:
            node = signature.nodes[node_id]
            if node.iri:
                values[node_id] = node.iri
                continue
            bound = row.get(compiled.variables[node_id])
            values[node_id] = None if bound is None else _value(bound)
            if isinstance(bound, ox.Literal):
                literals[node_id] = bound
        keep = True
        for traversal in compiled.traversals:
            subject, obj = values.get(traversal.subject), values.get(traversal.object)
            if subject is None or obj is None:
                continue
            if checker.nearest(traversal, subject, obj):
                continue
            if not traversal.optional_block:
                keep = False
                break
            for node_id in traversal.optional_block:
                values[node_id] = None
                literals.pop(node_id, None)
        if not keep:
            continue
        key = tuple(values[n] for n in node_ids)
        if key in seen:
            continue
        seen.add(key)
        matches.append(Match(values, literals=literals))
    # a row whose optional block was unbound duplicates a row that never bound it; and a row with a
    # bound block supersedes the unbound one for the same required nodes
    matches.sort(key=lambda m: tuple((v is None, v or "") for v in m.values()))
    return matches


def missing_class_report(store, signature: Signature, default_graph: Sequence[ox.NamedNode] | None) -> list[str]:
    """One sentence per class ``signature`` names that no loaded ontology (or the model) declares."""
    problems = []
    classes = sorted({c for node in signature.nodes.values() for c in node.classes})
    for cls in classes:
        term = ox.NamedNode(cls)
        declared = _query(
            store,
            "ASK { { %s a ?kind . VALUES ?kind { <http://www.w3.org/2002/07/owl#Class> "
            "<http://www.w3.org/2000/01/rdf-schema#Class> } } UNION { %s <http://www.w3.org/2000/01/rdf-schema#subClassOf> ?super }"
            " UNION { ?sub <http://www.w3.org/2000/01/rdf-schema#subClassOf> %s } }" % (term, term, term),
            default_graph,
        )
        if not declared:
            problems.append(
                f"signature {signature.id} ({signature.source_file}) names class {cls}, which no loaded ontology declares"
            )
    return problems
