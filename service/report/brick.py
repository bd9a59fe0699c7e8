"""What graphtwin made of a Brick model: the Brick classes and relations the alignment rules
(``queries/alignment/*-brick-*.rq``) did not align, the assumptions they made where the model is
ambiguous, and the points they could not place or link to data. Nothing is dropped silently.

Read from a loaded model's own graph and its ``inferred`` graph: unaligned classes (with what would
be needed; told official-but-unmodelled from misspelt given the official ontology), unread
relations, ``gt:AlignmentAssumption`` records, points without a column or unit, and temperature
points off the flow path. The rules for each: ``docs/report.md``, "The Brick report".
"""

from __future__ import annotations

import difflib
import re
from dataclasses import asdict, dataclass
from pathlib import Path

from rich.console import Console
from rich.table import Table

from service.errors import InputError, NotFoundError
from service.graph.alignment_derivation import rule_terms
from service.graph.namespaces import PREFIXES, compact_iri, local_name, namespace_of
from service.graph.rdf_io import parse_rdf, rdf_format
from service.graph.store import ONTOLOGY_GRAPH, GraphStore

__all__ = ["BRICK", "REC", "REF", "UnalignedClass", "UnreadRelation", "Assumption", "BrickReport",
           "brick_report", "official_brick_classes", "print_brick_report"]

BRICK = "https://brickschema.org/schema/Brick#"
REC = "https://w3id.org/rec#"
REF = "https://brickschema.org/schema/Brick/ref#"

_PREFIXES = f"""
PREFIX brick: <{BRICK}>
PREFIX saref: <https://saref.etsi.org/core/>
PREFIX fso:   <https://w3id.org/fso#>
PREFIX gt:    <https://w3id.org/graphtwin/ontology#>
PREFIX rdfs:  <http://www.w3.org/2000/01/rdf-schema#>
"""

_CLASSES = _PREFIXES + f"""
SELECT ?class (COUNT(DISTINCT ?node) AS ?count) (COUNT(DISTINCT ?unaligned) AS ?unaligned_count) WHERE {{
  GRAPH ?model {{ ?node a ?class }}
  FILTER(STRSTARTS(STR(?class), "{BRICK}") || STRSTARTS(STR(?class), "{REC}"))
  BIND(EXISTS {{ GRAPH ?inferred {{ ?node gt:derivedByRule ?rule }} }} AS ?named)
  BIND(EXISTS {{
    GRAPH ?ontology {{ ?class rdfs:subClassOf* brick:Air_Handling_Unit }}
    GRAPH ?model {{ ?node brick:hasPart|^brick:isPartOf|brick:hasPoint|^brick:isPointOf ?member }}
    GRAPH ?inferred {{ {{ ?member ?p2 ?o2 }} UNION {{ ?s2 ?q2 ?member }} }}
  }} AS ?container)
  BIND(IF(?named || ?container, ?none, ?node) AS ?unaligned)
}}
GROUP BY ?class
HAVING (COUNT(DISTINCT ?unaligned) > 0)
ORDER BY DESC(?unaligned_count) ?class
"""

_PREDICATES = f"""
SELECT ?predicate (COUNT(*) AS ?count) WHERE {{
  GRAPH ?model {{ ?s ?predicate ?o }}
  FILTER(STRSTARTS(STR(?predicate), "{BRICK}") || STRSTARTS(STR(?predicate), "{REF}"))
}}
GROUP BY ?predicate ORDER BY DESC(?count) ?predicate
"""

_ASSUMPTIONS = _PREFIXES + """
SELECT ?about ?assumption ?resolved_by ?rule WHERE {
  GRAPH ?inferred {
    ?record a gt:AlignmentAssumption ; gt:assumptionAbout ?about ; gt:assumption ?assumption ;
      gt:resolvedBy ?resolved_by ; gt:derivedByRule ?rule .
  }
}
ORDER BY ?rule ?about ?assumption
"""

#: Measuring points and commands the Brick rules derived (02/03), with their column and unit if any,
#: and whether a temperature point is on the flow path.
_POINTS = _PREFIXES + """
SELECT DISTINCT ?point ?series ?unit ?temperature ?water ?on_path WHERE {
  GRAPH ?inferred { ?point saref:observes|saref:controls ?property ; gt:derivedByRule ?rule }
  FILTER(?rule IN ("02-brick-sensors.rq", "03-brick-commands.rq"))
  OPTIONAL { GRAPH ?inferred { ?point gt:timeSeriesId ?series } }
  OPTIONAL { GRAPH ?inferred { ?point saref:isMeasuredIn ?unit } }
  BIND(EXISTS { GRAPH ?inferred { ?point a gt:TemperatureSensor } } AS ?temperature)
  BIND(EXISTS { GRAPH ?model { ?point a ?class } GRAPH ?ontology { ?class rdfs:subClassOf* brick:Water_Temperature_Sensor } }
       AS ?water)
  BIND(EXISTS { GRAPH ?inferred { { ?point fso:suppliesFluidTo ?next } UNION { ?previous fso:suppliesFluidTo ?point } } } AS ?on_path)
}
ORDER BY ?point
"""

_SUBSET_CLASSES = f"""
SELECT DISTINCT ?class WHERE {{
  GRAPH ?ontology {{ ?class a ?kind }}
  FILTER(STRSTARTS(STR(?class), "{BRICK}") || STRSTARTS(STR(?class), "{REC}"))
  FILTER(?kind IN (<http://www.w3.org/2002/07/owl#Class>, <http://www.w3.org/2000/01/rdf-schema#Class>))
}}
"""


@dataclass(frozen=True)
class UnalignedClass:
    """``unaligned`` of the model's ``count`` nodes of ``class_iri`` took no part in the alignment."""

    class_iri: str
    count: int
    unaligned: int
    needed: str


@dataclass(frozen=True)
class UnreadRelation:
    """No alignment rule reads ``predicate``; the model states it ``count`` times."""

    predicate: str
    count: int
    needed: str


@dataclass(frozen=True)
class Assumption:
    """A choice a rule made where the model is ambiguous, and the triple that would remove it."""

    about: str
    assumption: str
    resolved_by: str
    rule: str


@dataclass(frozen=True)
class BrickReport:
    model_name: str
    unaligned_classes: tuple[UnalignedClass, ...]
    unread_relations: tuple[UnreadRelation, ...]
    assumptions: tuple[Assumption, ...]
    points_without_column: tuple[str, ...]
    points_without_unit: tuple[str, ...]
    temperature_points_off_path: tuple[str, ...]
    water_points_unread: tuple[str, ...]

    @property
    def is_brick(self) -> bool:
        """Whether the model uses any Brick term the report could speak about."""
        return bool(self.unaligned_classes or self.unread_relations or self.assumptions
                    or self.points_without_column or self.points_without_unit or self.temperature_points_off_path
                    or self.water_points_unread)

    def to_dict(self) -> dict:
        return asdict(self)


def _rule_terms() -> frozenset[str]:
    """Every ``brick:`` / ``ref:`` / ``rec:`` term the alignment rules name (the relations they read)."""
    return frozenset(t for t in rule_terms() if t.startswith((BRICK, REF, REC)))


#: The schemes of the IRIs the report shortens (http(s) and urn: models alike).
_SCHEMES = r"(?:https?://|urn:)"
#: An IRI inside a sentence (up to the characters that end one there).
_IRI = re.compile(_SCHEMES + r"[^\s<>`'\"(),;]+")


#: Brick 1.x's own unit namespace, which Brick models state units in and QUDT does not know.
_BRICK_UNITS = "http://brickschema.org/schema/Brick/units#"


def _compact(iri: str) -> str:
    """A prefixed name where graphtwin knows the namespace (``unit:PERCENT``, Brick 1.x's units as
    ``bu:DEG_F``, which would read as the QUDT unit it is taken for), else the local name."""
    if iri.startswith(_BRICK_UNITS):
        return "bu:" + iri[len(_BRICK_UNITS):]
    compact = compact_iri(iri)
    return local_name(iri) if compact.startswith("<") else compact


def _turtle(text: str, own: dict[str, str]) -> str:
    """Triples as Turtle to paste: an IRI in a namespace graphtwin knows as its prefixed name
    (``unit:DEG_F``, QUDT's), one in the model's namespaces by ``own``'s prefix (``:mat_sensor``)."""
    def name(iri: str) -> str:
        known, namespace = compact_iri(iri), namespace_of(iri)
        return known if known[0] != "<" or namespace not in own else f"{own[namespace]}:{local_name(iri)}"

    return re.sub(r"<(" + _SCHEMES + r"[^\s<>]+)>", lambda m: name(m.group(1)), text)


def _short(iri: str) -> str:
    for prefix, namespace in (("brick:", BRICK), ("rec:", REC), ("ref:", REF)):
        if iri.startswith(namespace):
            return prefix + iri[len(namespace):]
    return iri


def _close_names(local: str, classes) -> list[str]:
    names = {local_name(k): k for k in classes}
    return [_short(names[c]) for c in difflib.get_close_matches(local, list(names), n=3, cutoff=0.75)]


def _class_hint(class_iri: str, known: set[str], official: frozenset[str] | None) -> str:
    if class_iri in known:
        return ("no alignment rule maps it to a SAREF/FSO device, property or flow node, so no signature can use it "
                "(a rule in queries/alignment/ and, for equipment, a component signature in signatures/)")
    local = local_name(class_iri)
    subset = "graphtwin's Brick subset (ontologies/brick-subset.ttl: the official Brick 1.4 classes the rules read)"
    if official is None:
        close = _close_names(local, known)
        hint = f" (if misspelt: {', '.join(close)}?)" if close else ""
        return (f"not in {subset}, so no rule reads it: a point or equipment graphtwin does not model, or a class "
                f"that is not official Brick{hint}; --brick-ontology Brick.ttl tells which")
    if class_iri in official:
        return ("official Brick, not in graphtwin's subset (ontologies/brick-subset.ttl): not modelled; a rule in "
                "queries/alignment/ (for equipment also a signature) would be needed")
    close = _close_names(local, official)
    return ("not official Brick (nor in graphtwin's subset): misspelt"
            + (f"? Closest official classes: {', '.join(close)}" if close else ", or from another vocabulary"))


def official_brick_classes(path: Path) -> frozenset[str]:
    """The Brick and RealEstateCore classes (``owl:Class`` / ``rdfs:Class``) an official ontology file
    declares (``Brick.ttl``; the RDF syntaxes models load in, by the file's suffix: :func:`rdf_format`).

    :raises InputError: naming the file, when it cannot be read, has no RDF suffix, or declares no such
        class; :class:`~service.errors.ModelLoadError` naming its line and column when it cannot be parsed.
    """
    path = Path(path)
    try:
        fmt, data = rdf_format(path.suffix), path.read_bytes()
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: {exc}") from None
    kinds = {"http://www.w3.org/2002/07/owl#Class", "http://www.w3.org/2000/01/rdf-schema#Class"}
    classes = frozenset(
        t.subject.value for t in parse_rdf(data, fmt, str(path))
        if t.predicate.value == "http://www.w3.org/1999/02/22-rdf-syntax-ns#type" and t.object.value in kinds
        and t.subject.value.startswith((BRICK, REC)))
    if not classes:
        raise InputError(f"{path}: declares no Brick or RealEstateCore class: not the official Brick ontology")
    return classes


def brick_report(store: GraphStore, model_name: str, official: frozenset[str] | None = None) -> BrickReport:
    """The report for model ``model_name`` loaded in ``store``; ``official``: the class IRIs of the
    official Brick ontology (:func:`official_brick_classes`), to tell official classes graphtwin does
    not model from misspelt ones.

    :raises NotFoundError: no model of that name in the store.
    """
    if not store.has_model(model_name):
        raise NotFoundError(f"no model {model_name!r} in the store (known: {', '.join(store.models()) or 'none'})")
    store.ensure_ontologies()
    graphs = {"model": store.model_graph(model_name), "inferred": store.inferred_graph(model_name),
              "ontology": ONTOLOGY_GRAPH}
    known = {row["class"].value for row in store.query(_SUBSET_CLASSES, substitutions={"ontology": ONTOLOGY_GRAPH})}
    classes = tuple(
        UnalignedClass(row["class"].value, int(row["count"].value), int(row["unaligned_count"].value),
                       _class_hint(row["class"].value, known, official))
        for row in store.query(_CLASSES, substitutions=graphs)
    )
    read = _rule_terms()
    relations = tuple(
        UnreadRelation(row["predicate"].value, int(row["count"].value),
                       "no alignment rule reads it: what it states does not reach the simulation model")
        for row in store.query(_PREDICATES, substitutions={"model": graphs["model"]})
        if row["predicate"].value not in read
    )
    assumptions = tuple(
        Assumption(row["about"].value, row["assumption"].value, row["resolved_by"].value, row["rule"].value)
        for row in store.query(_ASSUMPTIONS, substitutions={"inferred": graphs["inferred"]})
    )
    points = store.query(_POINTS, substitutions=graphs)
    return BrickReport(
        model_name=model_name, unaligned_classes=classes, unread_relations=relations, assumptions=assumptions,
        points_without_column=tuple(sorted({r["point"].value for r in points if "series" not in r})),
        points_without_unit=tuple(sorted({r["point"].value for r in points if "unit" not in r})),
        temperature_points_off_path=tuple(sorted({
            r["point"].value for r in points if r["temperature"].value == "true" and r["on_path"].value == "false"
            and r["water"].value == "false"})),
        water_points_unread=tuple(sorted({
            r["point"].value for r in points if r["water"].value == "true" and r["on_path"].value == "false"})),
    )


def print_brick_report(report: BrickReport, console: Console | None = None) -> None:
    """The report as tables (what ``graphtwin brick-report`` prints)."""
    console = console or Console()
    if not report.is_brick:
        console.print(f"{report.model_name}: no Brick terms the alignment could have missed; nothing to report.")
        return
    if report.unaligned_classes:
        table = Table(title="Brick classes not aligned (their nodes reach no signature)")
        for column in ("class", "nodes not aligned / all", "what would be needed"):
            table.add_column(column, overflow="fold")
        for c in report.unaligned_classes:
            table.add_row(_short(c.class_iri), f"{c.unaligned} / {c.count}", c.needed)
        console.print(table)
    if report.unread_relations:
        table = Table(title="Brick relations no alignment rule reads")
        for column in ("relation", "triples", "what it means"):
            table.add_column(column, overflow="fold")
        for r in report.unread_relations:
            table.add_row(_short(r.predicate), str(r.count), r.needed)
        console.print(table)
    if report.assumptions:
        texts = [(a.about, a.assumption, a.resolved_by, a.rule) for a in report.assumptions]
        iris = {iri for row in texts for text in row for iri in _IRI.findall(text)}
        namespaces = sorted({namespace_of(iri) for iri in iris if _compact(iri) == local_name(iri)})
        caption = ", ".join(([f"nodes by their local names, in {', '.join(namespaces)}"] if namespaces else [])
                            + ([f"bu: {_BRICK_UNITS}"] if any(i.startswith(_BRICK_UNITS) for i in iris) else []))
        # to paste: prefixed names, the model's own namespaces as ":" (then ns2:, …), declared below
        own = dict.fromkeys(namespace_of(i) for row in texts for i in _IRI.findall(row[2]) if compact_iri(i)[0] == "<")
        own = {namespace: "" if n == 0 else f"ns{n + 1}" for n, namespace in enumerate(own)}
        fixes = [_turtle(row[2], own) for row in texts]
        used = sorted({p for fix in fixes for p in re.findall(r"(?<![\w<#/:])([a-z]+):\w", fix) if p in PREFIXES})
        declared = [f"@prefix {p}: <{PREFIXES[p]}> ." for p in used] + [f"@prefix {p}: <{n}> ." for n, p in own.items()]
        caption = "; ".join(filter(None, [caption, "to paste the triples: " + " ".join(declared) if declared else ""]))
        table = Table(title="Assumptions made where the model is ambiguous", caption=caption or None)
        for column in ("about", "assumed", "state this to remove it", "rule"):
            table.add_column(column, overflow="fold")
        for (about, assumed, _, rule), fix in zip(texts, fixes):
            table.add_row(*(_IRI.sub(lambda m: _compact(m.group(0)), text) for text in (about, assumed)), fix,
                          _IRI.sub(lambda m: _compact(m.group(0)), rule))
        console.print(table)
    for title, points, needed in (
        ("Points with no column (ref:hasTimeseriesId or rdfs:label)", report.points_without_column,
         "their measurements cannot be read"),
        ("Points with no unit (brick:hasUnit)", report.points_without_unit,
         "state brick:hasUnit with a QUDT unit (a command in percent: unit:PERCENT; a fraction: unit:UNITLESS)"),
        ("Temperature points off the flow path (boundary inputs only)", report.temperature_points_off_path,
         "state which equipment's outlet they read (brick:isPointOf that equipment); a zone's or room's air "
         "stays an input: a unit's mixing box reads the return air from a brick:Return_Air_Temperature_Sensor "
         "of the unit"),
        ("Water temperature points no model reads", report.water_points_unread,
         "a coil model reads the water entering it (an entering or supply water point of the coil or its valve); "
         "no model gives a coil's leaving water, nor says which coil a unit's or plant's supply water reaches"),
    ):
        if points:
            console.print(f"[bold]{title}[/bold]: {needed}")
            for point in points:
                console.print(f"  {point}")
