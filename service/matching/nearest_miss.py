"""Why a signature matches nowhere: the required triples the graph cannot satisfy.

The pattern is grown from its modeled node, one required triple at a time (the first in file order
that touches the nodes already in), and matched at each size; a triple after which nothing matches
is what the graph lacks, set aside while the growing goes on. The sentence names each with the
nodes matched up to there and the triple a user would add, and lists the triples that hang on them.
Details: ``docs/matching.md``, "Why a pattern matches nowhere".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from service.graph.namespaces import compact_iri, local_name
from service.matching.matcher import Match, MatchSession, match_signature
from service.matching.signature import PatternTriple, Rule, Signature

if TYPE_CHECKING:
    import pyoxigraph as ox

    from service.matching.matcher import MatchStore

__all__ = ["nearest_miss"]

#: Nodes named in a sentence before "…".
_NAMED = 3


def _kind(signature: Signature, node_id: str) -> str:
    """The node as a reader knows it: its fixed IRI, its classes (" or "), or "literal" / "term"."""
    node = signature.nodes[node_id]
    if node.iri:
        return compact_iri(node.iri)
    return " or ".join(compact_iri(c) for c in node.classes) or ("literal" if node.literal else "term")


def _grown(signature: Signature) -> list[PatternTriple]:
    """The required triples in the order they join the modeled node's part of the pattern."""
    remaining = [t for t in signature.triples if not t.is_optional]
    inside, order = {signature.modeled_nodes[0]}, []
    while remaining:
        touching = next((t for t in remaining if t.subject in inside or t.object in inside), remaining[0])
        remaining.remove(touching)
        order.append(touching)
        inside |= {touching.subject, touching.object}
    return order


def _partial(signature: Signature, triples: Sequence[PatternTriple]) -> Signature:
    """``signature`` reduced to ``triples`` and the nodes they (and its modeled node) name."""
    used = {signature.modeled_nodes[0]} | {n for t in triples for n in (t.subject, t.object)}
    return replace(signature, nodes={n: v for n, v in signature.nodes.items() if n in used}, triples=tuple(triples),
                   modeled_nodes=signature.modeled_nodes[:1], inputs=(), outputs=(), parameters=(), splice=None)


def _instances(store: MatchStore, signature: Signature, node_id: str, session: MatchSession) -> list[Match]:
    """The graph's nodes that pattern node ``node_id`` alone matches (its classes, nothing joined)."""
    alone = replace(signature, nodes={node_id: signature.nodes[node_id]}, triples=(), modeled_nodes=(node_id,),
                    inputs=(), outputs=(), parameters=(), splice=None)
    return match_signature(store, alone, session=session)


def _names(matches: Sequence[Match], node_id: str) -> list[str]:
    return sorted({local_name(m[node_id]) for m in matches if m.get(node_id)})


def _term(signature: Signature, node_id: str) -> str:
    """A pattern node as SPARQL writes it: ``?id``, or its fixed IRI."""
    iri = signature.nodes[node_id].iri
    return compact_iri(iri) if iri else f"?{node_id}"


def _text(signature: Signature, triple: PatternTriple) -> str:
    return f"`{_term(signature, triple.subject)} {compact_iri(triple.predicate)} {_term(signature, triple.object)}`"


def _missing(signature: Signature, triple: PatternTriple, matched: Sequence[Match], reached: set[str]) -> str:
    """The missing ``triple`` in words, with what its ends are (the nodes ``matched`` for those
    ``reached``), and the triple to add: a matched node by name where it is the only one, else
    ``<id>`` (one of those listed: naming the first would pick among them for the user)."""
    ends, terms = [], []
    for node_id in (triple.subject, triple.object):
        names = _names(matched, node_id) if node_id in reached and not signature.nodes[node_id].iri else []
        if names:
            shown = " or ".join(names[:_NAMED]) + (f" (or {len(names) - _NAMED} more)" if len(names) > _NAMED else "")
            ends.append(f"?{node_id} {shown}")
            terms.append(names[0] if len(names) == 1 else f"<{node_id}>")
        elif signature.nodes[node_id].iri:
            ends.append(_term(signature, node_id))
            terms.append(_term(signature, node_id))
        else:
            ends.append(f"?{node_id} a {_kind(signature, node_id)}")
            terms.append(f"<{node_id}>")
    either = " either way" if triple.or_reverse else ""
    nearest = f", the nearest along it{either}" if triple.rule is Rule.TRAVERSE else ""
    return (f"no {_text(signature, triple)} with {ends[0]} and {ends[1]}{nearest} "
            f"(add `{terms[0]} {compact_iri(triple.predicate)} {terms[1]}`)")


def nearest_miss(store: MatchStore, signature: Signature, *,
                 default_graph: Sequence[ox.NamedNode] | None = None) -> str:
    """A sentence saying what the graph lacks for ``signature`` to match ("" when it matches): every
    required triple no match of those before it satisfies, and those that hang on them (unchecked)."""
    session = MatchSession(store, default_graph)
    anchor = signature.modeled_nodes[0]
    matched = match_signature(store, _partial(signature, ()), session=session)
    if not matched:
        return f"nothing in the graph is a {_kind(signature, anchor)} (its {anchor})"
    kept, reached, missing, hanging, unreached, introduced = [], {anchor}, [], [], set(), set()
    for triple in _grown(signature):
        if {triple.subject, triple.object} & unreached:
            hanging.append(triple)
            unreached |= {triple.subject, triple.object} - reached
            continue
        found = match_signature(store, _partial(signature, [*kept, triple]), session=session)
        if found:
            kept.append(triple)
            matched = found
            reached |= {triple.subject, triple.object}
        else:
            absent = [n for n in sorted({triple.subject, triple.object} - reached)
                      if not signature.nodes[n].iri and not _instances(store, signature, n, session)]
            nothing = "".join(f"the graph has no {_kind(signature, n)} at all (its ?{n}): " for n in absent)
            missing.append(nothing + _missing(signature, triple, matched, reached))
            introduced |= {triple.subject, triple.object} - reached
            unreached |= {triple.subject, triple.object} - reached
    if not missing:
        return ""
    described = {n for t in hanging for n in (t.subject, t.object)
                 if n in unreached - introduced and not signature.nodes[n].iri}
    kinds = ", ".join(f"?{n} a {_kind(signature, n)}" for n in sorted(described))
    then = (f"; then the triples that hang on it: {', '.join(_text(signature, t) for t in hanging)}"
            + (f" ({kinds})" if kinds else "")) if hanging else ""
    return "; ".join(missing) + then
