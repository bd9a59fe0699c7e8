"""Match a signature in a graph: its query parts, joined on shared nodes and on *nearest* traverses.

Nearness (Bjørnskov, Jradi & Wetter, Sec. 3.2: "follow the predicate until an instance of the class
is found"): ``s P+ o`` such that some path from ``s`` to ``o`` along ``P`` has no intermediate node
that is an instance of the searched-for end's allowed classes (:mod:`service.matching.compiler`),
found by a breadth-first search from the bound end that does not expand through blocking nodes. A
:class:`MatchSession` reads each predicate's edges, class's instances and part query once for all
signatures matched in one graph state; inside it a term is its text in SPARQL TSV results
(N-Triples syntax; "" when unbound). Matches are de-duplicated and sorted. Details and measured
costs: ``docs/matching.md``.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from itertools import repeat
from operator import itemgetter
from types import MappingProxyType
from typing import TYPE_CHECKING

import pyoxigraph as ox

from service.matching.compiler import CompiledQuery, QueryPart, Reads, Traversal, compile_signature
from service.matching.signature import Rule, Signature
from service.runtime import cyclic_gc_paused

if TYPE_CHECKING:
    from service.graph.backend import SparqlBackend
    from service.graph.store import GraphStore

    #: What the matcher queries: a graph store, one of its backends, or a bare pyoxigraph store.
    MatchStore = GraphStore | SparqlBackend | ox.Store

__all__ = ["Match", "MatchSession", "match_signature", "missing_class_report"]

_RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
_SUBCLASS = "http://www.w3.org/2000/01/rdf-schema#subClassOf"
_EQUIVALENT = "http://www.w3.org/2002/07/owl#equivalentClass"
_ROW = "\0row"  # column of the input row index while an optional block is joined
_UNBOUND = ""  # a row's term for a node its optional part left unbound
_COUNT_CAP = 10_000  # instance counts stop there: enough to choose a part's start node
_SCANNED_TRIPLES = 100_000  # a graph beyond the model with more is read by every query (see dataset_for)

Row = tuple  # the terms (TSV text) of a row's bound nodes, in the order of its columns


class Match(dict):
    """Pattern node id → bound IRI string / literal lexical form / None; ``literals`` keeps the
    bound :class:`pyoxigraph.Literal` of literal nodes (datatype, language). The matcher sets it on
    the matches that bind literals; the others share an empty read-only mapping (no ``__init__``
    argument: cheaper for many matches, ``docs/matching.md``)."""

    literals: Mapping[str, ox.Literal] = MappingProxyType({})


def _select(store: MatchStore, sparql: str, names: Sequence[str],
            default_graph: Sequence[ox.NamedNode] | None) -> list[Row]:
    """Rows of a SELECT projecting ``names`` (in that order) as tuples of term texts ("": unbound)."""
    if hasattr(store, "backend") and isinstance(getattr(store.backend, "store", None), ox.Store):
        store = store.backend.store  # the embedded store: read its TSV results, no term objects
    if isinstance(store, ox.Store):
        kwargs = {"default_graph": list(default_graph)} if default_graph is not None else {}
        lines = store.query(sparql, **kwargs).serialize(format=ox.QueryResultsFormat.TSV).decode().split("\n")
        if lines[0] != "\t".join(f"?{n}" for n in names):
            raise ValueError(f"expected the columns {names}, the query returned {lines[0]!r}")
        return [tuple(line.split("\t")) for line in lines[1:-1]]  # a newline ends every row
    return [tuple(_UNBOUND if (term := row.get(n)) is None else str(term) for n in names)
            for row in store.query(sparql, default_graph=default_graph)]


def _ask(store: MatchStore, sparql: str, default_graph: Sequence[ox.NamedNode] | None) -> bool:
    if isinstance(store, ox.Store):
        kwargs = {"default_graph": list(default_graph)} if default_graph is not None else {}
        return bool(store.query(sparql, **kwargs))
    return store.query(sparql, default_graph=default_graph)


def _integer(term: str) -> int:
    """The value of an integer's term text (a bare ``42`` or ``"42"^^<…#integer>``: a COUNT's answer)."""
    return int(term.split("^^")[0].strip('"'))


def _is_literal(term: str) -> bool:
    return term != _UNBOUND and term[0] != "<" and not term.startswith("_:")


class _Literals(dict):
    """Literal text (N-Triples, or TSV's bare numbers and booleans: all Turtle) → literal, parsed once."""

    def __missing__(self, text: str) -> ox.Literal:
        [quad] = ox.parse(f"<urn:s> <urn:p> {text} .".encode(), format=ox.RdfFormat.TURTLE)
        literal = self[text] = quad.object
        return literal


class _Values(dict):
    """Term text → the value a match gives it (IRI, ``_:id``, lexical form; None: unbound), made once."""

    def __init__(self, literals: _Literals):
        super().__init__({_UNBOUND: None})
        self.literals = literals

    def __missing__(self, text: str) -> str:
        value = self[text] = text[1:-1] if text[0] == "<" else text if text[0] == "_" else self.literals[text].value
        return value


def _getter(indices: Sequence[int]) -> Callable[[Row], object]:
    """A row's items at ``indices``, as a key: one item, or a tuple of several (or of none)."""
    return itemgetter(*indices) if indices else lambda row: ()


def _columns(indices: Sequence[int]) -> Callable[[Row], Row]:
    """A row's items at ``indices``, as a tuple."""
    if len(indices) == 1:
        index = indices[0]
        return lambda row: (row[index],)
    return _getter(indices)


def _text_without_comments(sparql: str) -> str:
    return "\n".join(line for line in sparql.splitlines() if not line.lstrip().startswith("#"))


class MatchSession:
    """One graph state's edges, class instances, part rows and nearest searches, shared by every
    signature matched in it (``store``: a :class:`~service.graph.store.GraphStore`, a backend or a bare
    pyoxigraph ``Store``; ``default_graph``: the graphs the patterns are matched in). ``literals``
    and ``values`` map term texts to literals and to match values, each made once. It keeps what it
    read: make a new session after the graph changes."""

    def __init__(self, store: MatchStore, default_graph: Sequence[ox.NamedNode] | None = None):
        self.store = store
        self.default_graph = list(default_graph) if default_graph is not None else None
        self._edges: dict[tuple[str, bool], dict[str, list[str]]] = {}
        self._class_instances: dict[str, frozenset[str]] = {}
        self._subclasses: dict[str, tuple[str, ...]] = {}
        self._compiled: dict[str, tuple[Signature, CompiledQuery]] = {}
        self._instances: dict[tuple[str, ...], frozenset[str]] = {}
        self._counts: dict[tuple[str, ...], int] = {}
        self._part_rows: dict[str, list[Row]] = {}
        self._near: dict[tuple, dict[str, frozenset[str]]] = {}
        self._graph_contents: dict[ox.NamedNode, tuple[frozenset[str], frozenset[str]] | None] = {}
        self._datasets: dict[Reads, list[ox.NamedNode] | None] = {}
        self.literals = _Literals()
        self.values = _Values(self.literals)

    def select(self, sparql: str, names: Sequence[str], reads: Reads) -> list[Row]:
        """Rows of a SELECT projecting ``names``, as tuples of term texts (see the module docstring),
        over the graphs that hold triples it ``reads`` (:meth:`dataset_for`)."""
        return _select(self.store, sparql, names, self.dataset_for(reads))

    def dataset_for(self, reads: Reads) -> list[ox.NamedNode] | None:
        """The session's graphs a query reading ``reads`` (predicate IRI → the objects its triples can
        take, None: any; :attr:`~service.matching.compiler.QueryPart.reads`) can match a triple in: the
        first graph (the model) always, each other one when it holds one of those predicates
        (``rdf:type``: with one of those classes) or is too large to look through (more than
        :data:`_SCANNED_TRIPLES`: a Brick model's inferred view). The answers are the same; a graph
        left out costs no lookups."""
        if self.default_graph is None:
            return None
        if reads not in self._datasets:
            first, *others = self.default_graph
            self._datasets[reads] = [first] + [g for g in others if self._holds(g, reads)]
        return self._datasets[reads]

    def _holds(self, graph: ox.NamedNode, reads: Reads) -> bool:
        if graph not in self._graph_contents:
            self._graph_contents[graph] = self._contents(graph)
        if self._graph_contents[graph] is None:
            return True
        predicates, classes = self._graph_contents[graph]
        return any(p in predicates and (p != _RDF_TYPE or objects is None or not classes.isdisjoint(objects))
                   for p, objects in reads)

    def _contents(self, graph: ox.NamedNode) -> tuple[frozenset[str], frozenset[str]] | None:
        """The predicates of ``graph`` and the classes typed in it; None when it holds more than
        :data:`_SCANNED_TRIPLES` triples (the scan stops there)."""
        query = (f"SELECT ?p (COUNT(*) AS ?n) WHERE {{ {{ SELECT ?p WHERE {{ ?s ?p ?o }} LIMIT {_SCANNED_TRIPLES + 1} }} }} "
                 "GROUP BY ?p")
        counted = _select(self.store, query, ("p", "n"), [graph])
        if sum(_integer(n) for _, n in counted) > _SCANNED_TRIPLES:
            return None
        classes = _select(self.store, f"SELECT DISTINCT ?c WHERE {{ ?s <{_RDF_TYPE}> ?c }}", ("c",), [graph])
        return (frozenset(p[1:-1] for p, _ in counted), frozenset(c[1:-1] for (c,) in classes if c.startswith("<")))

    def part_rows(self, part: QueryPart) -> list[Row]:
        """The distinct rows of ``part``'s query (over ``part.nodes``); a query another signature's
        part already ran (same text but for comments) is not run again."""
        key = _text_without_comments(part.text)
        if key not in self._part_rows:
            self._part_rows[key] = list(dict.fromkeys(self.select(part.text, part.nodes, part.reads)))
        return self._part_rows[key]

    def edges(self, predicate: str, forward: bool) -> dict[str, list[str]]:
        """Node → the nodes it links to along ``predicate`` (``forward``) or that link to it."""
        key = (predicate, forward)
        if key not in self._edges:
            successors: dict[str, list[str]] = defaultdict(list)
            predecessors: dict[str, list[str]] = defaultdict(list)
            query = f"SELECT ?a ?b WHERE {{ ?a {ox.NamedNode(predicate)} ?b }}"
            for a, b in self.select(query, ("a", "b"), ((predicate, None),)):
                successors[a].append(b)
                predecessors[b].append(a)
            self._edges[(predicate, True)] = successors
            self._edges[(predicate, False)] = predecessors
        return self._edges[key]

    def subclasses(self, classes: Collection[str]) -> dict[str, tuple[str, ...]]:
        """Class IRI → the IRIs of its subclasses (direct or not) in the session's graphs, equivalent
        classes (``owl:equivalentClass``, either way) counted as subclasses: a model's
        ``ex:Office owl:equivalentClass s4bldg:BuildingSpace`` makes its offices building spaces."""
        for cls in classes:
            if cls not in self._subclasses:
                path = f"(<{_SUBCLASS}>|<{_EQUIVALENT}>|^<{_EQUIVALENT}>)+"
                query = f"SELECT DISTINCT ?sub WHERE {{ ?sub {path} {ox.NamedNode(cls)} }}"
                found = self.select(query, ("sub",), ((_SUBCLASS, None), (_EQUIVALENT, None)))
                self._subclasses[cls] = tuple(sorted(sub[1:-1] for (sub,) in found if sub.startswith("<") and sub[1:-1] != cls))
        return {cls: self._subclasses[cls] for cls in classes}

    def compiled(self, signature: Signature) -> CompiledQuery:
        """``signature`` compiled with the session's class hierarchy and the instance counts of the
        nodes its part queries may start from (see :func:`compile_signature`)."""
        if signature.id not in self._compiled or self._compiled[signature.id][0] is not signature:
            classes = {c for node in signature.nodes.values() for c in node.classes}
            subclasses = self.subclasses(classes)
            in_exact_triples = {n for t in signature.triples if t.rule is not Rule.TRAVERSE
                                for n in (t.subject, t.object)}
            counts = {n: self.instance_count(tuple(dict.fromkeys(s for c in node.classes for s in (c, *subclasses[c]))))
                      for n, node in signature.nodes.items() if n in in_exact_triples and node.classes and not node.iri}
            self._compiled[signature.id] = (signature, compile_signature(signature, subclasses=subclasses, instance_counts=counts))
        return self._compiled[signature.id][1]

    def instance_count(self, classes: tuple[str, ...]) -> int:
        """How many nodes are typed with one of ``classes`` (listed subclasses included), counted up to
        :data:`_COUNT_CAP`: enough to tell which node a part's query should start from, at a bounded cost."""
        if classes not in self._counts:
            listed = " ".join(str(ox.NamedNode(c)) for c in classes)
            query = (f"SELECT (COUNT(*) AS ?n) WHERE {{ {{ SELECT ?x WHERE {{ VALUES ?c {{ {listed} }} "
                     f"?x <{_RDF_TYPE}> ?c }} LIMIT {_COUNT_CAP} }} }}")
            [(count,)] = self.select(query, ("n",), ((_RDF_TYPE, classes),))
            self._counts[classes] = _integer(count)
        return self._counts[classes]

    def instance_terms(self, classes: tuple[str, ...]) -> frozenset[str]:
        """The term texts of the instances of any of ``classes`` or their subclasses (the queries leave
        duplicates to the set, cheaper than DISTINCT)."""
        if classes not in self._instances:
            found: set[str] = set()
            for cls, subclasses in self.subclasses(classes).items():
                if cls not in self._class_instances:
                    typed = (cls, *subclasses)
                    listed = " ".join(str(ox.NamedNode(c)) for c in typed)
                    query = f"SELECT ?x WHERE {{ VALUES ?c {{ {listed} }} ?x <{_RDF_TYPE}> ?c }}"
                    self._class_instances[cls] = frozenset(x for (x,) in self.select(query, ("x",), ((_RDF_TYPE, typed),)))
                found |= self._class_instances[cls]
            self._instances[classes] = frozenset(found)
        return self._instances[classes]

    def instances(self, classes: tuple[str, ...]) -> frozenset[ox.NamedNode | ox.BlankNode | ox.Literal]:
        """The instances of any of ``classes`` or their subclasses, as terms."""
        return frozenset(map(self.term, self.instance_terms(classes)))

    def term(self, text: str) -> ox.NamedNode | ox.BlankNode | ox.Literal:
        """The term a term text (see the module docstring) stands for."""
        if text.startswith("<"):
            return ox.NamedNode(text[1:-1])
        if text.startswith("_:"):
            return ox.BlankNode(text[2:])
        return self.literals[text]

    def nearest(self, traversal: Traversal, starts: Iterable[str], forward: bool) -> dict[str, frozenset[str]]:
        """For each of ``starts`` (and every start searched before): the nodes other than itself it
        reaches along the traversal's predicate (``forward``) or that reach it, on a path whose
        intermediate nodes are no instances of its blocking classes."""
        searches = self._near.setdefault((traversal.predicate, traversal.blocking_classes, forward), {})
        new = [start for start in set(starts) if start not in searches]
        if new:
            adjacency = self.edges(traversal.predicate, forward)
            blocking = self.instance_terms(traversal.blocking_classes)
            for start in new:
                seen: set[str] = set()
                frontier = [start]
                while frontier:
                    reached = []
                    for node in frontier:
                        for nxt in adjacency.get(node, ()):
                            if nxt not in seen:
                                seen.add(nxt)
                                if nxt not in blocking:
                                    reached.append(nxt)
                    frontier = reached
                seen.discard(start)
                searches[start] = frozenset(seen)
        return searches

    def partners(self, traversal: Traversal, starts: Iterable[str]) -> dict[str, frozenset[str]]:
        """Each of ``starts`` (nodes of the traversal's :attr:`~Traversal.start` end) → its nearest
        partners as the triple is written; with ``or_reverse``, the instances of its far classes among
        them, and for a start that has none, those with the triple reversed."""
        starts = set(starts)
        written = not traversal.from_object  # from the subject: along the predicate
        found = self.nearest(traversal, starts, written)
        if not traversal.or_reverse:
            return found
        far = self.instance_terms(traversal.far_classes)
        found = {s: found[s] & far for s in starts}
        reversed_ = self.nearest(traversal, [s for s in starts if not found[s]], not written)
        return {s: found[s] or reversed_[s] & far for s in starts}


def _join(session: MatchSession, rows: list[Row], columns: list[str], parts: list[QueryPart],
          traversals: list[Traversal]) -> tuple[list[Row], list[str]]:
    """Extend ``rows`` (over ``columns``) by every part (on shared nodes, or on a traverse's nearest
    pairs) and keep the rows that satisfy every traverse: (rows, their columns; no rows when a part
    or traverse could not be joined). A part that is one class's instances is a set test."""
    pending, checks, columns = list(parts), list(traversals), list(columns)
    while rows and (pending or checks):
        bound = set(columns)
        check = next((t for t in checks if t.subject in bound and t.object in bound), None)
        if check is not None:
            start, far = columns.index(check.start), columns.index(check.far)
            nearest = session.partners(check, (r[start] for r in rows))
            rows = [r for r in rows if r[far] in nearest[r[start]]]
            checks.remove(check)
            continue
        part = next((p for p in pending if bound & set(p.nodes)), None)
        via = far = None
        if part is None:
            via = next((t for t in checks if t.start in bound and t.far not in bound
                        or t.far in bound and t.start not in bound and not t.or_reverse), None)
            if via is not None:
                far = via.far if via.start in bound else via.start
                part = next(p for p in pending if far in p.nodes)
        part = part or pending[0]
        pending.remove(part)
        if via is not None:
            checks.remove(via)
            if via.start in bound:
                start = columns.index(via.start)
                nearest = session.partners(via, (r[start] for r in rows))
            else:  # a plain traverse searched from its object: against the predicate
                start = columns.index(via.object)
                nearest = session.nearest(via, (r[start] for r in rows), False)
        shared = sorted(bound & set(part.nodes))
        if part.text is None:  # one class's instances
            node, instances = part.nodes[0], session.instance_terms(part.classes)
            if via is not None:
                partners = {s: [(p,) for p in nearest[s] & instances] for s in {r[start] for r in rows}}
                rows = [r + p for r in rows for p in partners[r[start]]]
            elif shared:
                column = columns.index(node)
                rows = [r for r in rows if r[column] in instances]
            else:
                rows = [r + (x,) for r in rows for x in instances]
        else:
            key = _getter([part.nodes.index(n) for n in shared])
            row_key = _getter([columns.index(n) for n in shared])
            extension = _columns([i for i, n in enumerate(part.nodes) if n not in bound])
            index: dict[object, list[Row]] = defaultdict(list)
            if via is None:
                for part_row in session.part_rows(part):
                    index[key(part_row)].append(extension(part_row))
                rows = [r + e for r in rows for e in index.get(row_key(r), ())]
            else:
                partner = part.nodes.index(far)
                for part_row in session.part_rows(part):
                    index[(part_row[partner], key(part_row))].append(extension(part_row))
                in_part = frozenset(p for p, _ in index)
                partners = {s: nearest[s] & in_part for s in {r[start] for r in rows}}
                rows = [r + e for r in rows for p in partners[r[start]] for e in index.get((p, row_key(r)), ())]
        columns += [n for n in part.nodes if n not in bound]
    return (rows, columns) if not checks and not pending else ([], columns)


def match_signature(
    store: MatchStore, signature: Signature, *, default_graph: Sequence[ox.NamedNode] | None = None,
    compiled: CompiledQuery | None = None, session: MatchSession | None = None,
) -> list[Match]:
    """Every match of ``signature`` (see the module docstring), sorted.

    :param store: a :class:`~service.graph.store.GraphStore`, a backend, or a bare pyoxigraph ``Store``.
    :param default_graph: the graphs the pattern is matched in (model + inferred + ontologies).
    :param session: share edges, instances, part rows and searches with other signatures matched in
        the same graph state (its store and graphs are used; a new one otherwise).
    """
    session = session or MatchSession(store, default_graph)
    compiled = compiled or session.compiled(signature)
    with cyclic_gc_paused():
        return _matches(signature, compiled, session)


def _matches(signature: Signature, compiled: CompiledQuery, session: MatchSession) -> list[Match]:
    """The required parts joined, each optional block with a traverse left-joined, as sorted matches."""
    required = [p for p in compiled.parts if p.block is None]
    rows, columns = _join(session, [()], [], required, [t for t in compiled.traversals if t.block is None])
    for number in range(len(compiled.blocks)):
        width = len(columns)
        extended, block_columns = _join(
            session, [r + (i,) for i, r in enumerate(rows)], columns + [_ROW],
            [p for p in compiled.parts if p.block == number], [t for t in compiled.traversals if t.block == number])
        joined = {r[width] for r in extended}
        unbound = (_UNBOUND,) * (len(block_columns) - width - 1)
        rows = [r[:width] + r[width + 1:] for r in extended] + [r + unbound for i, r in enumerate(rows) if i not in joined]
        columns += block_columns[width + 1:]
    return _as_matches(signature, session, rows, columns)


def _as_matches(signature: Signature, session: MatchSession, rows: list[Row], columns: list[str]) -> list[Match]:
    """The distinct matches the rows (over ``columns``) give, sorted by their values (None last).
    Values are made a column at a time and zipped into rows, so the per-row work runs in C loops."""
    node_ids = list(signature.nodes)
    found = [n for n in node_ids if not signature.nodes[n].iri and n in columns]
    distinct = list(dict.fromkeys(map(_columns([columns.index(n) for n in found]), rows)))
    value = session.values.__getitem__
    found_values = {n: list(map(value, map(itemgetter(i), distinct))) for i, n in enumerate(found)}
    in_node_order = [found_values[n] if n in found_values else [signature.nodes[n].iri or None] * len(distinct)
                     for n in node_ids]  # a fixed IRI, or None for a node never bound
    values = list(zip(*in_node_order))
    literal_columns = [(n, i) for i, n in enumerate(found) if signature.nodes[n].literal or signature.nodes[n].any]
    literals: dict[tuple, dict[str, ox.Literal]] = {}
    for terms, bound in zip(distinct, values) if literal_columns else ():
        if bound not in literals:
            literals[bound] = {n: session.literals[terms[i]] for n, i in literal_columns if _is_literal(terms[i])}
    if any(None in column for column in in_node_order):
        keys = zip(*(list(map({v: (v is None, v or "") for v in set(column)}.__getitem__, column))
                     if None in column else column for column in in_node_order))
        key_of = dict(zip(values, keys))
        order = sorted(key_of, key=key_of.__getitem__)
    else:
        order = sorted(set(values))
    matches = list(map(Match, map(zip, repeat(node_ids), order)))
    for match, bound in zip(matches, order) if literals else ():
        if literals[bound]:
            match.literals = literals[bound]
    return matches


def missing_class_report(store: MatchStore, signature: Signature,
                         default_graph: Sequence[ox.NamedNode] | None) -> list[str]:
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
