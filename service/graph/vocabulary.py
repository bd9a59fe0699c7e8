"""Misspelt ontology terms in a building model: classes, properties and values no loaded ontology declares.

A class, property or value in an ontology's namespace that the ontology does not declare is most
often a misspelling (``s4bldg:Sensr``, ``fso:suppliesFluidToo``, ``s4bldg:nominalAirflowRate``):
graphtwin's signatures then see less of the graph than its author wrote. Each such term gets one
sentence naming a node that uses it and the declared term of its kind (class, property, or a value a
property points to) its local name is closest to (the same letters apart from case, ``difflib``
ratio ≥ 0.85, or one edit apart outside Brick). The loaded ontologies are subsets of the official
ones, so a term is only called a misspelling where a declared term is that close, or where nothing
else lets a signature see the node.
"""

from __future__ import annotations

import difflib
import re
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import pyoxigraph as ox

from service.graph.namespaces import BRICK, OWL, RDF, RDFS, REF, local_name, namespace_of
from service.graph.rdf_io import first_use
from service.graph.spelling import one_edit_apart
from service.graph.store import ONTOLOGY_GRAPH, GraphStore

__all__ = ["misspelt_terms", "MisspeltTerms", "DeclaredTerms", "closest_declared", "with_term_locations"]

#: The ``rdf:type`` objects that declare a class, and those that declare a property.
_CLASS_TYPES = (OWL.Class, RDFS.Class)
_PROPERTY_TYPES = (OWL.ObjectProperty, OWL.DatatypeProperty, OWL.AnnotationProperty, RDF.Property)
#: ``difflib`` ratio from which a declared term's name counts as the one meant; the names of Brick
#: and what it ships (its ``ref:`` and RealEstateCore terms) lie closer to one another (an official
#: class graphtwin leaves out is up to 0.92 from one it loads), so there only a nearer name counts.
CLOSE_NAME_RATIO = 0.85
BRICK_CLOSE_NAME_RATIO = 0.95
_BRICK_NAMESPACES = (str(BRICK), str(REF), "https://w3id.org/rec#")


@dataclass(frozen=True)
class DeclaredTerms:
    """The local names ontology triples declare, per namespace: classes, properties, and the
    values a property can point to (every typed term that is not a property: classes, and
    individuals such as SAREF4BLDG's nominal properties)."""

    classes: dict[str, list[str]]
    properties: dict[str, list[str]]
    values: dict[str, list[str]]

    @classmethod
    def of(cls, store: GraphStore) -> DeclaredTerms:
        """The terms the store's loaded ontologies declare."""
        return cls.from_triples(store.graph_triples(ONTOLOGY_GRAPH))

    @classmethod
    def from_triples(cls, triples: Iterable[ox.Triple]) -> DeclaredTerms:
        types = defaultdict(set)
        for t in triples:
            if t.predicate == RDF.type and isinstance(t.subject, ox.NamedNode):
                types[t.subject.value].add(t.object)
        kinds = defaultdict(lambda: defaultdict(list))  # kind → namespace → local names
        for iri, declared_as in sorted(types.items()):
            is_property = bool(declared_as & set(_PROPERTY_TYPES))
            for kind, member in (("classes", bool(declared_as & set(_CLASS_TYPES))), ("properties", is_property),
                                 ("values", not is_property)):
                if member:
                    kinds[kind][namespace_of(iri)].append(local_name(iri))
        return cls(**{kind: dict(kinds[kind]) for kind in ("classes", "properties", "values")})


def closest_declared(term: str, declared: dict[str, list[str]]) -> str | None:
    """The declared term (``declared``: namespace → local names) of ``term``'s namespace its local
    name is closest to, if one is close."""
    names, name = declared.get(namespace_of(term), []), local_name(term)
    cutoff = BRICK_CLOSE_NAME_RATIO if namespace_of(term) in _BRICK_NAMESPACES else CLOSE_NAME_RATIO
    brick = namespace_of(term) in _BRICK_NAMESPACES
    close = ([n for n in names if n.lower() == name.lower()]
             or difflib.get_close_matches(name, names, n=1, cutoff=cutoff)
             or ([] if brick or len(name) < 3 else [n for n in names if one_edit_apart(name.lower(), n.lower())][:1]))
    return namespace_of(term) + close[0] if close else None


def _nodes(first: str, count: int) -> str:
    return first if count == 1 else f"{count} nodes, e.g. {first}"


@dataclass(frozen=True)
class MisspeltTerms:
    """What :func:`misspelt_terms` found: ``dropped`` the sentences about nodes a likely misspelt class
    leaves out of every component (an incomplete model), ``notes`` the rest."""

    dropped: list[str]
    notes: list[str]


def misspelt_terms(store: GraphStore, model_name: str) -> MisspeltTerms:
    """One sentence per undeclared class (``queries/undeclared-classes.rq``), property or property
    value (``queries/undeclared-terms.rq``) of model ``model_name`` that is likely misspelt: a class
    that is all a signature could see of the nodes it types (those nodes are in no component; with a
    declared class close to it, they were meant to be), a class, property or value whose name is close
    to a declared term. Brick classes with no loaded class that close point to ``graphtwin
    brick-report`` (graphtwin loads only the Brick classes its alignment maps)."""
    variables = store.graph_variables(model_name)
    class_rows = store.run_named_query("undeclared-classes", **variables)
    term_rows = store.run_named_query("undeclared-terms", **variables)
    found = MisspeltTerms([], [])
    if not class_rows and not term_rows:
        return found
    declared = DeclaredTerms.of(store)
    for row in class_rows:
        cls, unseen = row["class"].value, int(row["unseen_nodes"].value)
        meant = closest_declared(cls, declared.classes)
        hint = (f" (did you mean {meant}?)" if meant else
                " (graphtwin brick-report says what the Brick alignment needs)" if namespace_of(cls) == BRICK else "")
        if unseen:
            first = row["first_unseen"].value
            (found.dropped if meant else found.notes).append(
                f"{local_name(first)}: its class {cls} ({_nodes(first, unseen)}) is declared by no loaded ontology, "
                f"and the node has no other type a signature matches: no component models it{hint}")
        elif meant:
            first = row["first_node"].value
            found.notes.append(f"{local_name(first)}: its class {cls} ({_nodes(first, int(row['nodes'].value))}) is "
                               f"declared by no loaded ontology{hint}; the node is modelled from its other types and "
                               "properties")
    for row in term_rows:
        term, is_property = row["term"].value, row["position"].value == "property"
        meant = closest_declared(term, declared.properties if is_property else declared.values)
        if meant:
            first, uses = row["first_subject"].value, int(row["uses"].value)
            triples = "1 triple" if uses == 1 else f"{uses} triples"
            role = ("its property", "no signature follows it") if is_property else (
                "the value", "no signature matches it")
            found.notes.append(f"{local_name(first)}: {role[0]} {term} ({triples}, e.g. from {first}) is declared "
                               f"by no loaded ontology (did you mean {meant}?): {role[1]}")
    return found


def with_term_locations(sentences: Sequence[str], text: str, source_name: str) -> list[str]:
    """``sentences`` (an incomplete model's problems or notes), each misspelling among them (one that
    asks "did you mean") followed by where the model's source ``text`` first uses the term it is about,
    the first IRI it names whole: ``(model.ttl, line 12, column 5)``. The store keeps no positions."""
    located = []
    for sentence in sentences:
        term = re.search(r"\w+://[^\s()]+", sentence) if "(did you mean " in sentence else None
        where = first_use(text, term.group(0)) if term else None
        located.append(f"{sentence} ({source_name}, line {where[0]}, column {where[1]})" if where else sentence)
    return located
