"""Blank nodes as IRIs (skolemisation, RDF 1.1 Concepts §3.5)."""

from __future__ import annotations

from collections.abc import Iterable
from itertools import count

import pyoxigraph as ox

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
    triples = list(triples)
    names = {} if names is None else names
    numbers = count()
    taken: set[str] | None = None  # the IRIs of that form already used: found at the first blank node

    def iri(term):
        nonlocal taken
        if isinstance(term, ox.BlankNode):
            if term not in names:
                if taken is None:
                    taken = {node.value for t in triples for node in (t.subject, t.predicate, t.object)
                             if isinstance(node, ox.NamedNode) and node.value.startswith(prefix)}
                    taken.update(given.value for given in names.values())
                while (value := f"{prefix}{next(numbers)}") in taken:
                    pass
                taken.add(value)
                names[term] = ox.NamedNode(value)
            return names[term]
        return term

    return [ox.Triple(iri(t.subject), t.predicate, iri(t.object)) for t in triples]
