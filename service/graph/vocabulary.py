"""Misspelt ontology terms in a building model: classes and properties no loaded ontology declares.

A class or property in an ontology's namespace that the ontology does not declare is most often a
misspelling (``s4bldg:Sensr``, ``fso:suppliesFluidToo``); graphtwin's signatures then see less of the
graph than its author wrote. Each such term gets one sentence naming a node that uses it and the
declared term its local name is closest to (the same letters apart from case, or ``difflib`` ratio
≥ 0.85). The loaded ontologies are subsets of the official ones, so a term is only called a
misspelling where a declared term is that close, or where nothing else lets a signature see the node.
"""

from __future__ import annotations

import difflib
from collections import defaultdict
from dataclasses import dataclass

import pyoxigraph as ox

from service.graph.namespaces import BRICK, OWL, RDF, RDFS, local_name, namespace_of
from service.graph.store import ONTOLOGY_GRAPH, GraphStore

__all__ = ["misspelt_term_notes", "closest_declared"]

#: The ``rdf:type`` objects that declare a class, and those that declare a property.
_CLASS_TYPES = (OWL.Class, RDFS.Class)
_PROPERTY_TYPES = (OWL.ObjectProperty, OWL.DatatypeProperty, OWL.AnnotationProperty, RDF.Property)
#: ``difflib`` ratio from which a declared term's name counts as the one meant.
CLOSE_NAME_RATIO = 0.85


@dataclass(frozen=True)
class _DeclaredTerms:
    """The local names the loaded ontologies declare, per namespace, for classes and for properties."""

    classes: dict[str, list[str]]
    properties: dict[str, list[str]]

    @classmethod
    def of(cls, store: GraphStore) -> _DeclaredTerms:
        classes, properties = defaultdict(list), defaultdict(list)
        for t in store.graph_triples(ONTOLOGY_GRAPH):
            if t.predicate != RDF.type or not isinstance(t.subject, ox.NamedNode):
                continue
            kind = classes if t.object in _CLASS_TYPES else properties if t.object in _PROPERTY_TYPES else None
            if kind is not None:
                kind[namespace_of(t.subject.value)].append(local_name(t.subject.value))
        return cls(classes, properties)


def closest_declared(term: str, declared: dict[str, list[str]]) -> str | None:
    """The declared term (``declared``: namespace → local names) of ``term``'s namespace its local
    name is closest to, if one is close."""
    names, name = declared.get(namespace_of(term), []), local_name(term)
    close = ([n for n in names if n.lower() == name.lower()]
             or difflib.get_close_matches(name, names, n=1, cutoff=CLOSE_NAME_RATIO))
    return namespace_of(term) + close[0] if close else None


def _node_name(iri: str) -> str:
    return iri.replace("#", "/").rsplit("/", 1)[-1]


def _nodes(first: str, count: int) -> str:
    return first if count == 1 else f"{count} nodes, e.g. {first}"


def misspelt_term_notes(store: GraphStore, model_name: str) -> list[str]:
    """One sentence per undeclared class (``queries/undeclared-classes.rq``) or property
    (``queries/undeclared-properties.rq``) of model ``model_name`` that is likely misspelt: a class
    that is all a signature could see of the nodes it types (those nodes are in no component), a
    class or property whose name is close to a declared one. Official Brick classes outside
    graphtwin's subset point to ``graphtwin brick-report`` instead."""
    variables = store.graph_variables(model_name)
    class_rows = store.run_named_query("undeclared-classes", **variables)
    property_rows = store.run_named_query("undeclared-properties", **variables)
    if not class_rows and not property_rows:
        return []
    declared = _DeclaredTerms.of(store)
    notes = []
    for row in class_rows:
        cls, unseen = row["class"].value, int(row["unseen_nodes"].value)
        meant = None if namespace_of(cls) == BRICK else closest_declared(cls, declared.classes)
        hint = (" (graphtwin brick-report says what the Brick alignment needs)" if namespace_of(cls) == BRICK
                else f" (did you mean {meant}?)" if meant else "")
        if unseen:
            first = row["first_unseen"].value
            notes.append(f"{_node_name(first)}: its class {cls} ({_nodes(first, unseen)}) is declared by no loaded "
                         f"ontology, and the node has no other type a signature matches: no component models it{hint}")
        elif meant:
            first = row["first_node"].value
            notes.append(f"{_node_name(first)}: its class {cls} ({_nodes(first, int(row['nodes'].value))}) is "
                         f"declared by no loaded ontology{hint}; the node is modelled from its other types and "
                         "properties")
    for row in property_rows:
        prop = row["property"].value
        meant = closest_declared(prop, declared.properties)
        if meant:
            first, uses = row["first_subject"].value, int(row["uses"].value)
            triples = "1 triple" if uses == 1 else f"{uses} triples"
            notes.append(f"{_node_name(first)}: its property {prop} ({triples}, e.g. from {first}) is declared by no "
                         f"loaded ontology (did you mean {meant}?): no signature follows it")
    return notes
