"""Blank nodes as IRIs (skolemisation, RDF 1.1 Concepts §3.5)."""

from __future__ import annotations

from collections.abc import Iterable

import pyoxigraph as ox

__all__ = ["skolemize"]


def skolemize(triples: Iterable[ox.Triple], prefix: str,
              names: dict[ox.BlankNode, ox.NamedNode] | None = None) -> list[ox.Triple]:
    """Replace every blank node by the IRI ``prefix + n`` (n = 0, 1, … in order of first appearance).

    The order of a parse is deterministic, so the same document always gives the same IRIs.
    :param names: blank node → IRI given so far; filled in place (pass the same mapping for several
        documents whose blank nodes are one set, or to name them back afterwards).
    """
    names = {} if names is None else names

    def iri(term):
        if isinstance(term, ox.BlankNode):
            if term not in names:
                names[term] = ox.NamedNode(f"{prefix}{len(names)}")
            return names[term]
        return term

    return [ox.Triple(iri(t.subject), t.predicate, iri(t.object)) for t in triples]
