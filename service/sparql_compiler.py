"""Signature → SPARQL: one SELECT query per signature pattern.

* A node with allowed classes becomes ``?n rdf:type/rdfs:subClassOf* ?n__class`` with
  ``VALUES ?n__class { … }`` over its classes (subclasses match; several classes are alternatives).
  A fixed-IRI node is the IRI itself; literal and ``any`` nodes are plain variables.
* An ``exact`` triple is a triple pattern.
* ``optional`` triples (and optional traverses) form OPTIONAL blocks: optional triples connected
  through nodes that appear *only* in optional triples form ONE block, with those nodes' class
  restrictions inside, so a chain value node → value → unit binds all together or not at all.
* A ``traverse`` triple becomes the property path ``?s P+ ?o``: reachability. The *nearest*
  condition — no intermediate node on the path is an instance of the searched-for end's allowed
  classes (the end the signature does not model; both ends' when both or neither are modelled) — is
  not expressible on property paths: written as ``FILTER NOT EXISTS`` or ``MINUS`` over two paths it
  is either explosive (> 600 s at 100k triples) or wrong on recirculation loops (every candidate on
  a loop lies "behind" another). :mod:`service.signature_matcher` checks it exactly on the rows the
  query returns, with a search over the predicate's edges that may not pass through an instance of
  the end classes; the compiled query records which triples need it (:attr:`CompiledQuery.traversals`).

Terms from signatures are serialised through pyoxigraph (``str(NamedNode(iri))``), which validates
and escapes them: an IRI with a space or ``>`` is refused with a ``ValueError`` naming it.
"""

from __future__ import annotations

from dataclasses import dataclass

import pyoxigraph as ox

from .namespaces import PREFIXES
from .signature import PatternTriple, Rule, Signature

__all__ = ["CompiledQuery", "Traversal", "compile_signature"]

_RDF_TYPE = "<http://www.w3.org/1999/02/22-rdf-syntax-ns#type>"
_SUBCLASS = "<http://www.w3.org/2000/01/rdf-schema#subClassOf>"


@dataclass(frozen=True)
class Traversal:
    """A traverse triple the matcher must check for nearness: ``subject`` reaches ``object`` along
    ``predicate`` without passing an instance of ``blocking_classes``; ``optional_block`` lists the
    nodes that become unbound when an optional traverse fails (empty for a required one)."""

    subject: str
    predicate: str
    object: str
    blocking_classes: tuple[str, ...]
    optional_block: tuple[str, ...] = ()


@dataclass(frozen=True)
class CompiledQuery:
    """``text``: the SELECT query; ``variables``: pattern node id → SPARQL variable name (without
    ``?``); ``traversals``: the nearness checks left to the matcher."""

    signature_id: str
    text: str
    variables: dict[str, str]
    traversals: tuple[Traversal, ...]


def _iri(value: str, where: str) -> str:
    try:
        return str(ox.NamedNode(value))
    except ValueError as exc:
        raise ValueError(f"{where}: {value!r} is not a valid IRI ({exc})") from None


def _short(iri_text: str) -> str:
    bare = iri_text.strip("<>")
    for prefix, namespace in PREFIXES.items():
        if bare.startswith(namespace) and bare[len(namespace):].replace("_", "a").replace("-", "a").isalnum():
            return f"{prefix}:{bare[len(namespace):]}"
    return iri_text


def compile_signature(signature: Signature) -> CompiledQuery:
    """Compile ``signature``'s pattern (see the module docstring).

    :raises ValueError: a class, predicate or fixed IRI is not a valid IRI (named in the message).
    """
    where = f"signature {signature.id} ({signature.source_file})"
    variables = {node_id: node_id for node_id in signature.nodes}

    def term(node_id: str) -> str:
        node = signature.nodes[node_id]
        return _short(_iri(node.iri, where)) if node.iri else f"?{node_id}"

    def class_restriction(node_id: str) -> list[str]:
        node = signature.nodes[node_id]
        if not node.classes:
            return []
        classes = " ".join(_short(_iri(c, where)) for c in node.classes)
        return [
            f"# {node_id}: an instance of {' or '.join(_short(_iri(c, where)) for c in node.classes)} (or a subclass)",
            f"VALUES ?{node_id}__class {{ {classes} }}",
            f"?{node_id} rdf:type/rdfs:subClassOf* ?{node_id}__class .",
        ]

    def triple_pattern(triple: PatternTriple) -> list[str]:
        predicate = _short(_iri(triple.predicate, where))
        subject, obj = term(triple.subject), term(triple.object)
        if triple.rule is Rule.TRAVERSE:
            return [
                f"# traverse: {triple.subject} {predicate}+ {triple.object} (nearest: checked by the matcher)",
                f"{subject} {predicate}+ {obj} .",
            ]
        return [f"{subject} {predicate} {obj} ."]

    required = [t for t in signature.triples if not t.is_optional]
    optional = [t for t in signature.triples if t.is_optional]
    required_nodes = {signature.modeled_nodes[0]}
    for t in required:
        required_nodes.update((t.subject, t.object))
    for node_id in signature.nodes:
        if not any(node_id in (t.subject, t.object) for t in signature.triples):
            required_nodes.add(node_id)

    # order required parts outward from the anchor so each step joins on a bound variable
    lines: list[str] = []
    placed: set[str] = set()
    pending = list(required)
    frontier = [signature.modeled_nodes[0]]
    for node_id in frontier:
        lines += class_restriction(node_id)
        placed.add(node_id)
    while pending:
        index = next((i for i, t in enumerate(pending) if t.subject in placed or t.object in placed), 0)
        triple = pending.pop(index)
        lines += triple_pattern(triple)
        for node_id in (triple.subject, triple.object):
            if node_id not in placed:
                lines += class_restriction(node_id)
                placed.add(node_id)
    for node_id in sorted(required_nodes - placed):
        lines += class_restriction(node_id)
        placed.add(node_id)

    # optional blocks: connected through nodes that occur only in optional triples
    blocks: list[list[PatternTriple]] = []
    for triple in optional:
        joined = [b for b in blocks if any(
            n in (t.subject, t.object) for t in b for n in (triple.subject, triple.object) if n not in required_nodes
        )]
        merged = [triple] + [t for b in joined for t in b]
        blocks = [b for b in blocks if b not in joined] + [merged]
    traversals: list[Traversal] = []
    for block in sorted(blocks, key=lambda b: signature.triples.index(b[-1])):
        block = sorted(block, key=signature.triples.index)
        own = sorted({n for t in block for n in (t.subject, t.object) if n not in required_nodes},
                     key=list(signature.nodes).index)
        inner: list[str] = []
        done: set[str] = set()
        for triple in block:
            inner += triple_pattern(triple)
            for node_id in (triple.subject, triple.object):
                if node_id in own and node_id not in done:
                    inner += class_restriction(node_id)
                    done.add(node_id)
        lines.append("OPTIONAL {")
        lines += [f"  {line}" for line in inner]
        lines.append("}")
        for triple in block:
            if triple.rule is Rule.TRAVERSE:
                traversals.append(_traversal(signature, triple, tuple(own)))
    for triple in required:
        if triple.rule is Rule.TRAVERSE:
            traversals.append(_traversal(signature, triple, ()))

    projected = " ".join(f"?{v}" for v in variables.values() if not signature.nodes[v].iri)
    prefix_lines = "\n".join(f"PREFIX {p}: <{ns}>" for p, ns in PREFIXES.items())
    body = "\n".join(f"  {line}" for line in lines)
    text = (
        f"{prefix_lines}\n# signature {signature.id}: {signature.label}\n"
        f"SELECT DISTINCT {projected} WHERE {{\n{body}\n}}\n"
    )
    for node_id, node in signature.nodes.items():
        if node.iri:
            variables[node_id] = ""
    return CompiledQuery(signature.id, text, variables, tuple(traversals))


def _traversal(signature: Signature, triple: PatternTriple, block: tuple[str, ...]) -> Traversal:
    """The searched-for end is the one the signature does not model (a fan looks for its nearest
    upstream sensor, a coil for its nearest downstream fan, even past another coil); when both or
    neither end is modelled, both ends' classes block."""
    ends = [triple.subject, triple.object]
    searched = [n for n in ends if n not in signature.modeled_nodes] or ends
    if len(searched) == 2:
        searched = ends
    classes = tuple(c for n in searched for c in signature.nodes[n].classes)
    return Traversal(triple.subject, triple.predicate, triple.object, tuple(dict.fromkeys(classes)), block)
