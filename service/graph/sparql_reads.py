"""Which triples a SPARQL query can read: the predicates of its patterns and the objects each can
take, so that the alignment's rule scheduler (:mod:`service.graph.alignment_derivation`) re-runs a
query only when a triple it could match was added.

The answer over-approximates and never misses: a predicate or object given by a variable reads any
unless a ``VALUES`` block, a ``FILTER(?v IN (…))`` or a ``FILTER(STRSTARTS(STR(?p), "…"))`` conjunct
of its group or an enclosing one restricts it; property paths, negated property sets, ``UNDEF`` and
numbers read more. Subjects are not looked at. Queries are parsed with rdflib's SPARQL parser
(parsing only; Oxigraph evaluates them). Every rule: ``docs/alignment.md``, What a rule reads.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache

from rdflib import XSD, Literal, URIRef, Variable
from rdflib.paths import AlternativePath, InvPath, MulPath, NegatedPath, Path, SequencePath
from rdflib.plugins.sparql import prepareQuery
from rdflib.plugins.sparql.parserutils import CompValue

__all__ = ["IriPrefix", "QueryReads", "query_reads"]


class IriPrefix(str):
    """A restriction of a variable to the IRIs that start with this text."""


#: variable → the constants it is restricted to, or the prefix of the IRIs it is (no entry: unrestricted).
_Restrictions = Mapping[Variable, frozenset[URIRef | Literal | IriPrefix]]


@dataclass(frozen=True)
class QueryReads:
    """The triples a query can match: for each predicate it names, the objects its patterns can take
    (``None``: any object); any object of the predicates starting with one of
    ``predicate_prefixes``; every triple when ``any_predicate`` (a pattern's predicate is open)."""

    objects: Mapping[str, frozenset[str] | None]
    any_predicate: bool = False
    predicate_prefixes: tuple[str, ...] = ()

    def may_read(self, added: Mapping[str, Iterable[str]]) -> bool:
        """Whether any of the triples ``added`` (predicate IRI → the IRIs or lexical forms of their
        objects) can take part in the query's answer."""
        if self.any_predicate:
            return bool(added)
        for predicate, objects in added.items():
            if predicate in self.objects:
                read = self.objects[predicate]
                if read is None or not read.isdisjoint(objects):
                    return True
            if predicate.startswith(self.predicate_prefixes):
                return True
        return False


#: rdflib's SPARQL grammar (pyparsing) is not safe to use from two threads at once: the first
#: parses of two models loaded side by side failed with parse errors on valid rules.
RDFLIB_PARSER_LOCK = threading.Lock()


@lru_cache(maxsize=None)
def query_reads(text: str) -> QueryReads:
    """What the SPARQL query ``text`` can read (module docstring); safe to call from several threads.

    :raises pyparsing.ParseException: when ``text`` is not SPARQL rdflib can parse.
    """
    with RDFLIB_PARSER_LOCK:
        algebra = prepareQuery(text).algebra["p"]
    collector = _Collector()
    collector.walk(algebra, {})
    objects = {p: None if o is None else frozenset(o) for p, o in collector.objects.items()}
    return QueryReads(objects, collector.any_predicate, tuple(sorted(collector.predicate_prefixes)))


class _Collector:
    def __init__(self) -> None:
        self.objects: dict[str, set[str] | None] = {}
        self.any_predicate = False
        self.predicate_prefixes: set[str] = set()

    def _read(self, predicate: str, objects: Iterable[str] | None) -> None:
        if predicate in self.objects and self.objects[predicate] is None:
            return
        if objects is None:
            self.objects[predicate] = None
        else:
            self.objects.setdefault(predicate, set()).update(objects)

    def walk(self, node: object, inherited: _Restrictions) -> None:
        if isinstance(node, list | tuple):
            for item in node:
                self.walk(item, inherited)
            return
        if not isinstance(node, CompValue):
            return
        if node.name in ("Project", "SelectQuery", "SubSelect") and inherited:
            projected = set(node.get("PV") or ())
            inherited = {v: c for v, c in inherited.items() if v in projected}
        restrictions = _merge(inherited, _provided(node))
        if node.name == "BGP":
            for triple in node["triples"]:
                self._pattern(triple, restrictions)
        for key, child in node.items():
            if node.name == "LeftJoin" and key == "p2":
                # OPTIONAL { P FILTER(e) }: rdflib makes e the left join's condition
                self.walk(child, _merge(restrictions, _in_conjuncts(node.get("expr"))))
                continue
            if key in ("graph", "_evalfn"):
                # (NOT) EXISTS: rdflib keeps the translated pattern as an attribute, the parse tree
                # (without its filters) as the item
                child = vars(node).get(key, child)
            if key not in ("_vars", "triples", "_evalfn"):
                self.walk(child, restrictions)

    def _pattern(self, triple: Iterable, restrictions: _Restrictions) -> None:
        _subject, predicate, obj = triple
        if isinstance(predicate, Variable):
            constants = restrictions.get(predicate, ())
            if not constants or not all(isinstance(c, URIRef | IriPrefix) for c in constants):
                self.any_predicate = True
            for constant in constants:
                if isinstance(constant, IriPrefix):
                    self.predicate_prefixes.add(str(constant))
                elif isinstance(constant, URIRef):
                    self._read(str(constant), None)
        elif isinstance(predicate, Path):
            self._path(predicate)
        elif _constant(obj):
            self._read(str(predicate), [str(obj)])
        elif isinstance(obj, Variable) and obj in restrictions and not any(isinstance(c, IriPrefix) for c in restrictions[obj]):
            self._read(str(predicate), [str(c) for c in restrictions[obj]])
        else:
            self._read(str(predicate), None)

    def _path(self, path: Path | URIRef) -> None:
        """A property path reads any object of each predicate in it."""
        if isinstance(path, NegatedPath):
            self.any_predicate = True
        elif isinstance(path, SequencePath | AlternativePath):
            for arg in path.args:
                self._path(arg)
        elif isinstance(path, InvPath):
            self._path(path.arg)
        elif isinstance(path, MulPath):
            self._path(path.path)
        elif isinstance(path, URIRef):
            self._read(str(path), None)
        else:
            self.any_predicate = True


def _merge(outer: _Restrictions, inner: _Restrictions) -> _Restrictions:
    """Both restrictions hold: intersect where both restrict a variable to constants; where one is a
    prefix (:class:`IriPrefix`), keep the other (a superset of what both allow)."""
    merged = dict(outer)
    for var, constants in inner.items():
        if var not in merged:
            merged[var] = constants
        elif any(isinstance(c, IriPrefix) for c in constants):
            continue
        elif any(isinstance(c, IriPrefix) for c in merged[var]):
            merged[var] = constants
        else:
            merged[var] = merged[var] & constants
    return merged


def _provided(node: CompValue) -> _Restrictions:
    """Restrictions that hold on every row of ``node``: its ``VALUES`` tables and ``IN`` filter
    conjuncts, through joins, the left side of ``OPTIONAL``/``MINUS``, and both sides of ``UNION``."""
    name = node.name
    if name == "ToMultiSet" and node["p"].name == "values":
        return _values_table([row for row in node["p"]["res"]])
    if name == "Join":
        return _merge(_provided(node["p1"]), _provided(node["p2"]))
    if name in ("LeftJoin", "Minus"):
        return _provided(node["p1"])
    if name == "Union":
        left, right = _provided(node["p1"]), _provided(node["p2"])
        return {v: left[v] | right[v] for v in left.keys() & right.keys()}
    if name == "Filter":
        return _merge(_provided(node["p"]), _in_conjuncts(node["expr"]))
    if name in ("Extend", "Distinct", "Reduced", "OrderBy", "Slice"):
        return _provided(node["p"])
    return {}


def _values_table(rows: list[Mapping[Variable, object]]) -> _Restrictions:
    """The variables every row binds to a constant, with the constants (a row with ``UNDEF`` frees its variable)."""
    if not rows:
        return {}
    variables = set.intersection(*(set(row) for row in rows))
    return {v: frozenset(row[v] for row in rows) for v in variables if all(_constant(row[v]) for row in rows)}


def _in_conjuncts(expr: object) -> _Restrictions:
    """``?v IN (constant, …)`` and ``STRSTARTS(STR(?v), "prefix")`` conjuncts of a filter expression."""
    if not isinstance(expr, CompValue):
        return {}
    if expr.name == "ConditionalAndExpression":
        restrictions = _in_conjuncts(expr["expr"])
        for other in expr.get("other") or ():
            restrictions = _merge(restrictions, _in_conjuncts(other))
        return restrictions
    if (expr.name == "RelationalExpression" and expr.get("op") == "IN" and isinstance(expr["expr"], Variable)
            and all(_constant(c) for c in expr["other"])):
        return {expr["expr"]: frozenset(expr["other"])}
    if (expr.name == "Builtin_STRSTARTS" and isinstance(text := expr["arg1"], CompValue) and text.name == "Builtin_STR"
            and isinstance(text["arg"], Variable) and isinstance(expr["arg2"], Literal)):
        return {text["arg"]: frozenset({IriPrefix(expr["arg2"])})}
    return {}


def _constant(term: object) -> bool:
    """Whether a term restricts an object by its text: an IRI or a string literal (a number's text
    is not canonical — ``1.0`` and ``1.00`` are one value — so it restricts nothing)."""
    return isinstance(term, URIRef) or (isinstance(term, Literal) and term.datatype in (None, XSD.string))
