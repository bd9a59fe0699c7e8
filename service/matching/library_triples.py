"""The signature library as triples, so SPARQL can ask which models apply where.

Each signature is ``<sig> a gt:Signature | gt:EffectSignature`` (:func:`~service.matching.signature.signature_iri`)
with its pattern nodes, pattern triples, port and parameter mappings and splice as resources minted
under ``<sig>/node/…``, ``<sig>/triple/N``, ``<sig>/input/P``, ``<sig>/output/P``,
``<sig>/parameter/N`` (vocabulary in ``ontologies/graphtwin.ttl``): no blank nodes, so two writes of
one library are equal. ``queries/models-for-class.rq`` reads this graph with the ontology graph's
class hierarchy. The full shape: ``docs/matching.md`` (*The library as triples*).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import pyoxigraph as ox

from service.graph.namespaces import DCTERMS, GT, RDF, RDFS, XSD
from service.graph.store import SIGNATURE_GRAPH, GraphStore
from service.matching.signature import Rule, Signature
from service.resources import signatures_dir

__all__ = ["signature_triples", "library_triples", "load_signature_library_into", "ensure_signature_library"]

_RULES = {Rule.EXACT: GT.Exact, Rule.TRAVERSE: GT.Traverse, Rule.OPTIONAL: GT.Optional}


def _source_name(path: Path | None) -> str | None:
    """The signature file relative to the library folder (its name when it lies elsewhere)."""
    if path is None:
        return None
    try:
        return path.resolve().relative_to(signatures_dir().resolve()).as_posix()
    except ValueError:
        return path.name


def signature_triples(signature: Signature) -> list[ox.Triple]:
    """Every triple describing ``signature`` (shape: ``docs/matching.md``)."""
    sig = ox.NamedNode(signature.iri)

    def node(node_id: str) -> ox.NamedNode:
        return ox.NamedNode(f"{signature.iri}/node/{node_id}")

    triples = [
        ox.Triple(sig, RDF.type, GT.EffectSignature if signature.kind == "effect" else GT.Signature),
        ox.Triple(sig, DCTERMS.identifier, ox.Literal(signature.id)),
        ox.Triple(sig, RDFS.label, ox.Literal(signature.label)),
        ox.Triple(sig, GT.complexity, ox.Literal(str(signature.complexity), datatype=XSD.integer)),
    ]
    if signature.comment:
        triples.append(ox.Triple(sig, RDFS.comment, ox.Literal(signature.comment)))
    if signature.model is not None:
        triples.append(ox.Triple(sig, GT.modelClass, ox.Literal(signature.model)))
    if signature.fmu is not None:
        triples.append(ox.Triple(sig, GT.fmuFile, ox.Literal(_source_name(signature.fmu))))
    source = _source_name(signature.source_file)
    if source is not None:
        triples.append(ox.Triple(sig, GT.sourceFile, ox.Literal(source)))

    for pattern_node in signature.nodes.values():
        iri = node(pattern_node.id)
        triples += [
            ox.Triple(sig, GT.hasPatternNode, iri),
            ox.Triple(iri, RDF.type, GT.PatternNode),
            ox.Triple(iri, GT.nodeId, ox.Literal(pattern_node.id)),
        ]
        triples += [ox.Triple(iri, GT.allowedClass, ox.NamedNode(c)) for c in pattern_node.classes]
        if pattern_node.iri is not None:
            triples.append(ox.Triple(iri, GT.fixedIri, ox.NamedNode(pattern_node.iri)))
        if pattern_node.literal:
            triples.append(ox.Triple(iri, RDF.type, GT.LiteralPatternNode))
        if pattern_node.any:
            triples.append(ox.Triple(iri, RDF.type, GT.AnyTermPatternNode))
    triples += [ox.Triple(sig, GT.modelsNode, node(n)) for n in signature.modeled_nodes]

    for index, pattern in enumerate(signature.triples):
        iri = ox.NamedNode(f"{signature.iri}/triple/{index}")
        triples += [
            ox.Triple(sig, GT.hasPatternTriple, iri),
            ox.Triple(iri, RDF.type, GT.PatternTriple),
            ox.Triple(iri, GT.patternSubject, node(pattern.subject)),
            ox.Triple(iri, GT.patternPredicate, ox.NamedNode(pattern.predicate)),
            ox.Triple(iri, GT.patternObject, node(pattern.object)),
            ox.Triple(iri, GT.rule, _RULES[pattern.rule]),
        ]
        if pattern.is_optional:
            triples.append(ox.Triple(iri, GT.mayBeAbsent, ox.Literal(True)))
        if pattern.or_reverse:
            triples.append(ox.Triple(iri, GT.orReverse, ox.Literal(True)))
        triples += [ox.Triple(iri, GT.stopsAt, ox.NamedNode(c)) for c in pattern.stop_at]

    for mapping in signature.inputs:
        iri = ox.NamedNode(f"{signature.iri}/input/{mapping.port}")
        triples += [
            ox.Triple(sig, GT.hasInput, iri),
            ox.Triple(iri, RDF.type, GT.PortMapping),
            ox.Triple(iri, GT.portName, ox.Literal(mapping.port)),
            ox.Triple(iri, GT.sourceNode, node(mapping.source)),
            ox.Triple(iri, GT.quantity, ox.Literal(mapping.quantity)),
        ]
    for mapping in signature.outputs:
        iri = ox.NamedNode(f"{signature.iri}/output/{mapping.port}")
        triples += [
            ox.Triple(sig, GT.hasOutput, iri),
            ox.Triple(iri, RDF.type, GT.PortMapping),
            ox.Triple(iri, GT.portName, ox.Literal(mapping.port)),
            ox.Triple(iri, GT.atNode, node(mapping.node)),
            ox.Triple(iri, GT.quantity, ox.Literal(mapping.quantity)),
        ]
    for parameter in signature.parameters:
        iri = ox.NamedNode(f"{signature.iri}/parameter/{parameter.name}")
        triples += [
            ox.Triple(sig, GT.hasParameterMapping, iri),
            ox.Triple(iri, RDF.type, GT.ParameterMapping),
            ox.Triple(iri, GT.parameterName, ox.Literal(parameter.name)),
            ox.Triple(iri, GT.valueNode, node(parameter.node)),
        ]
        if parameter.unit_node is not None:
            triples.append(ox.Triple(iri, GT.unitNode, node(parameter.unit_node)))

    if signature.splice is not None:
        splice = signature.splice
        triples += [
            ox.Triple(sig, GT.spliceNode, node(splice.node)),
            ox.Triple(sig, GT.splicePort, ox.Literal(splice.port)),
            ox.Triple(sig, GT.spliceSide, ox.Literal(splice.side)),
            ox.Triple(sig, GT.canAppear, ox.Literal("true" if signature.can_appear else "false", datatype=XSD.boolean)),
        ]
        triples += [ox.Triple(sig, GT.hostModel, ox.Literal(m)) for m in splice.host_models]
    return triples


def library_triples(library: Mapping[str, Signature]) -> list[ox.Triple]:
    """Triples of every signature in ``library``, by id."""
    return [t for key in sorted(library) for t in signature_triples(library[key])]


def load_signature_library_into(store: GraphStore, library: Mapping[str, Signature]) -> int:
    """Replace the signature graph of ``store`` with ``library`` in one transaction; returns the
    number of triples written (:func:`ensure_signature_library` writes only when it differs)."""
    triples = library_triples(library)
    store.write_graph(SIGNATURE_GRAPH, triples)
    return len(triples)


def ensure_signature_library(store: GraphStore, library: Mapping[str, Signature]) -> bool:
    """Make the signature graph of ``store`` describe ``library``; writes only when it differs.

    :returns: whether it wrote.
    """
    triples = library_triples(library)
    if set(triples) == set(store.graph_triples(SIGNATURE_GRAPH)):
        return False
    store.write_graph(SIGNATURE_GRAPH, triples)
    return True
