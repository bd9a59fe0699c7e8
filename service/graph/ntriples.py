"""N-Triples text as the store's writes and the alignment hand it over: whole graphs as triples, as
text, or as text in chunks of whole lines (not joined: ``docs/graph-store.md``, N-Triples hand-over)."""

from __future__ import annotations

from collections.abc import Iterable

import pyoxigraph as ox

__all__ = ["GraphTriples", "ntriples_chunks", "triple_list"]

#: A graph's triples as the store's writes take them: triples, N-Triples text (bytes), or N-Triples
#: text in chunks of whole lines (a list of bytes, as :func:`service.graph.alignment.inferred_ntriples`
#: returns it).
GraphTriples = Iterable[ox.Triple] | bytes | list[bytes]


def ntriples_chunks(triples: GraphTriples) -> list[bytes]:
    """``triples`` (:data:`GraphTriples`) as N-Triples text in chunks of whole lines."""
    if isinstance(triples, bytes):
        return [triples]
    triples = list(triples)
    if triples and isinstance(triples[0], bytes):
        return triples
    return [ox.serialize(triples, format=ox.RdfFormat.N_TRIPLES)] if triples else []


def triple_list(triples: GraphTriples) -> list[ox.Triple]:
    """``triples`` (:data:`GraphTriples`) as a list of triples (N-Triples text parsed)."""
    triples = [triples] if isinstance(triples, bytes) else list(triples)
    if triples and isinstance(triples[0], bytes):
        return [quad.triple for chunk in triples for quad in ox.parse(chunk, format=ox.RdfFormat.N_TRIPLES)]
    return triples
