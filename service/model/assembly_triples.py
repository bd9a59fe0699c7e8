"""The assembled model written back as triples, linked to the building nodes it models.

``<assembly> a gt:AssembledModel`` (:func:`assembly_iri`) with its ``gt:hasComponent``,
``gt:hasConnection``, ``gt:hasBoundaryInput`` and ``gt:hasTarget``; each component
``gt:instanceOf`` its signature and ``gt:represents`` its building nodes; each parameter carries its
name, unit, bounds, default and ``gt:mappedValue`` (a ``gt:MappedParameter``) or is a
``gt:EstimatedParameter``. Vocabulary in ``ontologies/graphtwin.ttl``; the full shape:
``docs/assembly.md`` (*The assembled model as triples*).
"""

from __future__ import annotations

import pyoxigraph as ox

from service.graph.namespaces import GT, GTR, RDF, RDFS, XSD
from service.model.assembled_model import AssembledModel, ParameterRef

__all__ = ["assembly_iri", "assembly_triples", "parameter_iri"]


def assembly_iri(model_name: str) -> ox.NamedNode:
    return ox.NamedNode(f"{GTR}model/{model_name}/assembly")


def parameter_iri(ref: ParameterRef) -> ox.NamedNode:
    return ox.NamedNode(f"{ref.component}/parameter/{ref.name}")


def _double(value: float) -> ox.Literal:
    return ox.Literal(repr(float(value)), datatype=XSD.double)


def assembly_triples(model: AssembledModel, model_name: str) -> list[ox.Triple]:
    """All triples describing ``model``; IRIs minted under ``gtr:model/<name>/``."""
    root = assembly_iri(model_name)
    triples = [ox.Triple(root, RDF.type, GT.AssembledModel)]
    if model.building_graph:
        triples.append(ox.Triple(root, GT.assembledFrom, ox.NamedNode(model.building_graph)))
    for iri, instance in model.components.items():
        node = ox.NamedNode(iri)
        triples += [
            ox.Triple(root, GT.hasComponent, node),
            ox.Triple(node, RDF.type, GT.ComponentInstance),
            ox.Triple(node, GT.instanceOf, ox.NamedNode(instance.signature.iri)),
            ox.Triple(node, RDFS.label, ox.Literal(f"{instance.signature.id} at {instance.node}")),
        ]
        triples += [ox.Triple(node, GT.represents, ox.NamedNode(n)) for n in instance.modeled_nodes]
    for index, connection in enumerate(model.connections):
        edge = ox.NamedNode(f"{root.value}/connection/{index}")
        triples += [
            ox.Triple(root, GT.hasConnection, edge),
            ox.Triple(edge, RDF.type, GT.Connection),
            ox.Triple(edge, GT.fromComponent, ox.NamedNode(connection.source)),
            ox.Triple(edge, GT.fromPort, ox.Literal(connection.source_port)),
            ox.Triple(edge, GT.toComponent, ox.NamedNode(connection.target)),
            ox.Triple(edge, GT.toPort, ox.Literal(connection.target_port)),
        ]
    triples += [ox.Triple(root, GT.hasBoundaryInput, ox.NamedNode(i)) for i in model.boundary_inputs]
    triples += [ox.Triple(ox.NamedNode(i), RDF.type, GT.BoundaryInput) for i in model.boundary_inputs]
    triples += [ox.Triple(root, GT.hasTarget, ox.NamedNode(i)) for i in model.targets]
    triples += [ox.Triple(ox.NamedNode(i), RDF.type, GT.CalibrationTarget) for i in model.targets]
    for ref in model.mapped_parameters + model.estimated_parameters:
        triples += _parameter_triples(ref)
    return triples


def _parameter_triples(ref: ParameterRef) -> list[ox.Triple]:
    node = parameter_iri(ref)
    spec = ref.spec
    triples = [
        ox.Triple(ox.NamedNode(ref.component), GT.hasParameter, node),
        ox.Triple(node, RDF.type, GT.Parameter),
        ox.Triple(node, GT.parameterName, ox.Literal(spec.name)),
        ox.Triple(node, GT.unit, ox.Literal(spec.unit)),
        ox.Triple(node, GT.lowerBound, _double(spec.lower)),
        ox.Triple(node, GT.upperBound, _double(spec.upper)),
        ox.Triple(node, GT.defaultValue, _double(spec.default)),
    ]
    if spec.description:
        triples.append(ox.Triple(node, RDFS.comment, ox.Literal(spec.description)))
    if ref.value is not None:
        triples += [ox.Triple(node, RDF.type, GT.MappedParameter), ox.Triple(node, GT.mappedValue, _double(ref.value))]
    else:
        triples.append(ox.Triple(node, RDF.type, GT.EstimatedParameter))
    return triples
