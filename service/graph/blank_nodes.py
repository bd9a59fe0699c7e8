"""Blank nodes as IRIs (skolemisation, RDF 1.1 Concepts §3.5)."""

from __future__ import annotations

from collections.abc import Iterable
from itertools import count

import pyoxigraph as ox

from service.runtime import cyclic_gc_paused

__all__ = ["skolemize"]


def skolemize(triples: Iterable[ox.Triple], prefix: str,
              names: dict[ox.BlankNode, ox.NamedNode] | None = None) -> list[ox.Triple]:
    """Replace every blank node by the IRI ``prefix + n`` (n = 0, 1, … in order of first appearance),
    skipping every n whose IRI the ``triples`` or ``names`` already hold: a new IRI never names a
    node the document has (a model exported from the store, its blank nodes now such IRIs, loaded
    again with blank nodes added keeps its nodes apart).

    The order of a parse is deterministic, so the same document always gives the same IRIs.
    :param names: blank node → IRI given so far; filled in place (pass the same mapping for several
        documents whose blank nodes are one set, or to name them back afterwards).
    """
    with cyclic_gc_paused():  # a million triples and their terms: no cycles, and a collection re-scans them all
        return _skolemized(list(triples), prefix, {} if names is None else names)


def _skolemized(triples: list[ox.Triple], prefix: str, names: dict[ox.BlankNode, ox.NamedNode]) -> list[ox.Triple]:
    """:func:`skolemize` of a list of its own, renamed in place (``names`` filled in place)."""
    blank = ox.BlankNode
    # most triples of a model hold no blank node: those are kept as they are (docs/graph-store.md)
    with_blank = [i for i, t in enumerate(triples) if type(t.subject) is blank or type(t.object) is blank]
    if not with_blank:
        return triples
    taken = {node.value for t in triples for node in (t.subject, t.predicate, t.object)
             if type(node) is ox.NamedNode and node.value.startswith(prefix)}
    taken.update(given.value for given in names.values())
    numbers = count()

    def iri(term):
        if type(term) is not blank:
            return term
        named = names.get(term)
        if named is None:
            while (value := f"{prefix}{next(numbers)}") in taken:
                pass
            taken.add(value)
            named = names[term] = ox.NamedNode(value)
        return named

    for i in with_blank:
        t = triples[i]
        triples[i] = ox.Triple(iri(t.subject), t.predicate, iri(t.object))
    return triples
