"""Match a signature in a graph: its query parts, joined on shared nodes and on *nearest* traverses.

Nearness (the paper's "follow the predicate until an instance of the class is found"), exactly:
``s P+ o`` such that some path from ``s`` to ``o`` along ``P`` has no intermediate node that is an
instance of the searched-for end's allowed classes (see :mod:`service.sparql_compiler`). The
condition is the same read in either direction, so the matcher searches from whichever end is
already bound: a breadth-first search over the predicate's edges that does not expand through
blocking nodes; the nodes it reaches are that end's nearest partners. Searches never expand a node
twice, so loops (return air mixed back into the supply) terminate and give the right answer: a
sensor on a loop finds the equipment right before it, not everything on the loop.

A :class:`MatchSession` reads each traversed predicate's edge list, each class's instances and
subclasses ONCE and caches every search, so matching a whole library costs one query per pattern
part plus one per predicate and class, and one search per distinct start node. It keeps what it read:
make a new session after the graph changes.

The compiled pattern is cut at its traverse triples (:attr:`CompiledQuery.parts`): the required
parts are joined on their shared nodes and on the nearest pairs of the required traverses (a node
with no nearest partner drops the row); each optional block holding a traverse is left-joined the
same way and binds all together or not at all. Matches are de-duplicated and sorted.
"""

from __future__ import annotations

import gc
from collections import defaultdict, deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import pyoxigraph as ox

from .signature import Signature
from .sparql_compiler import CompiledQuery, QueryPart, Traversal, compile_signature
from .store import drain

__all__ = ["Match", "MatchSession", "match_signature", "missing_class_report"]

_RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
_SUBCLASS = "http://www.w3.org/2000/01/rdf-schema#subClassOf"
_ROW = "\0row"  # key of the input row index while an optional block is joined


class Match(dict):
    """Pattern node id → bound IRI string / literal lexical form / None; ``literals`` keeps the
    bound :class:`pyoxigraph.Literal` of literal nodes (datatype, language)."""

    def __init__(self, *args, literals: dict[str, ox.Literal] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.literals = literals or {}


def _select(store, sparql: str, names: Sequence[str], default_graph) -> list[tuple]:
    """Rows of a SELECT projecting ``names`` (in that order) as tuples of terms (None: unbound)."""
    if hasattr(store, "backend") and isinstance(getattr(store.backend, "store", None), ox.Store):
        store = store.backend.store  # the embedded store: read solutions without building dicts
    if isinstance(store, ox.Store):
        kwargs = {"default_graph": list(default_graph)} if default_graph is not None else {}
        return drain(store.query(sparql, **kwargs), tuple)
    return [tuple(row.get(n) for n in names) for row in store.query(sparql, default_graph=default_graph)]


def _ask(store, sparql: str, default_graph) -> bool:
    if isinstance(store, ox.Store):
        kwargs = {"default_graph": list(default_graph)} if default_graph is not None else {}
        return bool(store.query(sparql, **kwargs))
    return store.query(sparql, default_graph=default_graph)


def _value(term) -> str:
    if isinstance(term, ox.BlankNode):
        return f"_:{term.value}"
    return term.value


class MatchSession:
    """One graph state's edges, class instances and nearest searches, shared by every signature
    matched in it (``store``: a :class:`~service.store.GraphStore`, a backend or a bare pyoxigraph
    ``Store``; ``default_graph``: the graphs the patterns are matched in)."""

    def __init__(self, store, default_graph: Sequence[ox.NamedNode] | None = None):
        self.store = store
        self.default_graph = list(default_graph) if default_graph is not None else None
        self._edges: dict[tuple[str, bool], dict[object, list]] = {}
        self._class_instances: dict[str, frozenset] = {}
        self._subclasses: dict[str, tuple[str, ...]] = {}
        self._compiled: dict[str, tuple[Signature, CompiledQuery]] = {}
        self._instances: dict[tuple[str, ...], frozenset] = {}
        self._near: dict[tuple, dict[object, frozenset]] = {}

    def select(self, sparql: str, names: Sequence[str]) -> list[tuple]:
        return _select(self.store, sparql, names, self.default_graph)

    def edges(self, predicate: str, forward: bool) -> dict[object, list]:
        """Node → the nodes it links to along ``predicate`` (``forward``) or that link to it."""
        key = (predicate, forward)
        if key not in self._edges:
            successors: dict[object, list] = defaultdict(list)
            predecessors: dict[object, list] = defaultdict(list)
            for a, b in self.select(f"SELECT ?a ?b WHERE {{ ?a {ox.NamedNode(predicate)} ?b }}", ("a", "b")):
                successors[a].append(b)
                predecessors[b].append(a)
            self._edges[(predicate, True)] = successors
            self._edges[(predicate, False)] = predecessors
        return self._edges[key]

    def subclasses(self, classes) -> dict[str, tuple[str, ...]]:
        """Class IRI → the IRIs of its subclasses (direct or not) in the session's graphs."""
        for cls in classes:
            if cls not in self._subclasses:
                query = f"SELECT DISTINCT ?sub WHERE {{ ?sub <{_SUBCLASS}>+ {ox.NamedNode(cls)} }}"
                self._subclasses[cls] = tuple(sorted(
                    r[0].value for r in self.select(query, ("sub",)) if isinstance(r[0], ox.NamedNode)))
        return {cls: self._subclasses[cls] for cls in classes}

    def compiled(self, signature: Signature) -> CompiledQuery:
        """``signature`` compiled with the session's class hierarchy (see :func:`compile_signature`)."""
        if signature.id not in self._compiled or self._compiled[signature.id][0] is not signature:
            classes = {c for node in signature.nodes.values() for c in node.classes}
            self._compiled[signature.id] = (signature, compile_signature(signature, self.subclasses(classes)))
        return self._compiled[signature.id][1]

    def instances(self, classes: tuple[str, ...]) -> frozenset:
        """Instances of any of ``classes`` or their subclasses."""
        if classes not in self._instances:
            found: set = set()
            for cls in classes:
                if cls not in self._class_instances:
                    query = f"SELECT DISTINCT ?x WHERE {{ ?x <{_RDF_TYPE}>/<{_SUBCLASS}>* {ox.NamedNode(cls)} }}"
                    rows = self.select(query, ("x",))
                    self._class_instances[cls] = frozenset(r[0] for r in rows)
                found |= self._class_instances[cls]
            self._instances[classes] = frozenset(found)
        return self._instances[classes]

    def nearest(self, traversal: Traversal, start, forward: bool) -> frozenset:
        """The nodes ``start`` reaches along the traversal's predicate (``forward``) or that reach it,
        on a path whose intermediate nodes are no instances of its blocking classes."""
        searches = self._near.setdefault((traversal.predicate, traversal.blocking_classes, forward), {})
        found = searches.get(start)
        if found is None:
            adjacency = self.edges(traversal.predicate, forward)
            blocking = self.instances(traversal.blocking_classes)
            seen: set = set()
            queue = deque([start])
            while queue:
                for nxt in adjacency.get(queue.popleft(), ()):
                    if nxt not in seen:
                        seen.add(nxt)
                        if nxt not in blocking:
                            queue.append(nxt)
            found = searches[start] = frozenset(seen)
        return found


def _part_rows(session: MatchSession, part: QueryPart) -> list[dict]:
    return [{n: t for n, t in zip(part.nodes, row) if t is not None}
            for row in session.select(part.text, part.nodes)]


def _join(session: MatchSession, rows: list[dict], parts: list[QueryPart], traversals: list[Traversal]) -> list[dict]:
    """Extend ``rows`` by every part (on shared nodes, or on a traverse's nearest pairs) and keep
    the rows that satisfy every traverse. A part that is one class's instances is a set test."""
    pending, checks = list(parts), list(traversals)
    bound = set(rows[0]) if rows else set()
    while rows and (pending or checks):
        check = next((t for t in checks if t.subject in bound and t.object in bound), None)
        if check is not None:
            nearest, subject, obj = session.nearest, check.subject, check.object
            rows = [r for r in rows if r[obj] in nearest(check, r[subject], True)]
            checks.remove(check)
            continue
        part = next((p for p in pending if bound & set(p.nodes)), None)
        via = far = None
        if part is None:
            via = next((t for t in checks if (t.subject in bound) != (t.object in bound)), None)
            if via is not None:
                far = via.object if via.subject in bound else via.subject
                part = next(p for p in pending if far in p.nodes)
        part = part or pending[0]
        pending.remove(part)
        shared = sorted(bound & set(part.nodes))
        if part.text is None:  # one class's instances
            node, instances = part.nodes[0], session.instances(part.classes)
            if via is not None:
                near, forward = (via.subject, True) if via.subject in bound else (via.object, False)
                rows = [{**r, node: partner} for r in rows
                        for partner in session.nearest(via, r[near], forward) if partner in instances]
            elif shared:
                rows = [r for r in rows if r.get(node) in instances]
            else:
                rows = [{**r, node: x} for r in rows for x in instances]
        else:
            index: dict[tuple, list[dict]] = defaultdict(list)
            if via is None:
                for row in _part_rows(session, part):
                    index[tuple(row.get(n) for n in shared)].append(row)
                rows = [{**r, **f} for r in rows for f in index.get(tuple(r.get(n) for n in shared), ())]
            else:
                near, forward = (via.subject, True) if via.subject in bound else (via.object, False)
                for row in _part_rows(session, part):
                    index[(row.get(far),) + tuple(row.get(n) for n in shared)].append(row)
                rows = [
                    {**r, **f}
                    for r in rows for partner in session.nearest(via, r[near], forward)
                    for f in index.get((partner,) + tuple(r.get(n) for n in shared), ())
                ]
        if via is not None:
            checks.remove(via)
        bound |= set(part.nodes)
    return rows if not checks and not pending else []


@contextmanager
def _cyclic_gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector: a join allocates millions of tuples, dicts and sets (none
    in a reference cycle), and every collection of the oldest generation re-scans them all; at 1M
    triples that was a third of the matching time. Reference counting still frees everything."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def match_signature(
    store, signature: Signature, *, default_graph: Sequence[ox.NamedNode] | None = None,
    compiled: CompiledQuery | None = None, session: MatchSession | None = None,
) -> list[Match]:
    """Every match of ``signature`` (see the module docstring), sorted.

    :param store: a :class:`~service.store.GraphStore`, a backend, or a bare pyoxigraph ``Store``.
    :param default_graph: the graphs the pattern is matched in (model + inferred + ontologies).
    :param session: share edges, instances and searches with other signatures matched in the same
        graph state (its store and graphs are used; a new one otherwise).
    """
    session = session or MatchSession(store, default_graph)
    compiled = compiled or session.compiled(signature)
    with _cyclic_gc_paused():
        return _matches(signature, compiled, session)


def _matches(signature: Signature, compiled: CompiledQuery, session: MatchSession) -> list[Match]:
    """The required parts joined, each optional block with a traverse left-joined, as sorted matches."""
    required = [p for p in compiled.parts if p.block is None]
    rows = _join(session, [{}], required, [t for t in compiled.traversals if t.block is None])
    for number in range(len(compiled.blocks)):
        numbered = [{**r, _ROW: i} for i, r in enumerate(rows)]
        extended = _join(session, numbered, [p for p in compiled.parts if p.block == number],
                         [t for t in compiled.traversals if t.block == number])
        joined = {r.pop(_ROW) for r in extended}
        rows = extended + [r for i, r in enumerate(rows) if i not in joined]
    node_ids = list(signature.nodes)
    fixed = {n: node.iri for n, node in signature.nodes.items() if node.iri}
    literal_nodes = [n for n, node in signature.nodes.items() if node.literal or node.any]
    text: dict = {}
    seen: set[tuple] = set()
    values: list[tuple] = []
    literals: list[dict] = []
    for row in rows:
        key = tuple(
            fixed[n] if n in fixed else None if t is None else text.get(t) or text.setdefault(t, _value(t))
            for n, t in ((n, row.get(n)) for n in node_ids)
        )
        if key not in seen:
            seen.add(key)
            values.append(key)
            literals.append({n: row[n] for n in literal_nodes if isinstance(row.get(n), ox.Literal)})
    order = sorted(range(len(values)), key=lambda i: tuple((v is None, v or "") for v in values[i]))
    return [Match(zip(node_ids, values[i]), literals=literals[i]) for i in order]


def missing_class_report(store, signature: Signature, default_graph: Sequence[ox.NamedNode] | None) -> list[str]:
    """One sentence per class ``signature`` names that no loaded ontology (or the model) declares."""
    problems = []
    classes = sorted({c for node in signature.nodes.values() for c in node.classes})
    for cls in classes:
        term = ox.NamedNode(cls)
        declared = _ask(
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
