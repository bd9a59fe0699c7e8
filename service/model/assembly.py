"""Model assembly: match every signature in the building graph, instantiate and wire the components.

Bjørnskov, Jradi & Wetter, Sec. 3.3: every match becomes a component instance, its inputs wired to
the outputs at their source nodes (:mod:`service.model.wiring`); then boundary inputs = measuring
devices with no connected input, calibration targets = measuring devices with one (Eq. 1), and
parameters to estimate = all parameters − those mapped from the graph (Eq. 2). Where signatures
claim the same node, the more specific classes win, then the higher complexity, the more nodes, the
id; recorded or requested effects are spliced in (:mod:`service.model.effect_splicing`). Every choice
and gap is a sentence in ``AssembledModel.notes``. Details: ``docs/assembly.md``.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping

import pyoxigraph as ox

from service.components.library import SignatureLibrary
from service.components.measuring_device import MeasuringDevice
from service.errors import AssemblyError, IncompleteModelError, UnitError
from service.graph.namespaces import FSO, RDFS, distinct_local_names
from service.graph.store import GraphStore
from service.graph.units import closest_unit_hint, unit_spec
from service.graph.vocabulary import misspelt_terms
from service.matching.matcher import MatchSession, match_signature, missing_class_report
from service.matching.signature import QUANTITY_UNITS, PatternTriple, Rule, Signature, required_outward
from service.model.assembled_model import AssembledModel, ComponentInstance, Connection, mapped_values_outside_bounds
from service.model.effect_splicing import EffectRequest, recorded_effects, splice_effect
from service.model.wiring import (
    MatchValues,
    best_match_per_anchor,
    instantiate,
    measured_outputs,
    modeled_nodes,
    short_name,
    split_parameters,
    wire,
)
from service.runtime import cyclic_gc_paused

__all__ = ["assemble"]

#: Class IRI → its number of superclasses (the more, the more specific).
ClassDepth = Callable[[str], int]


def assemble(
    store: GraphStore,
    model_name: str,
    *,
    library: Mapping[str, Signature] | None = None,
    max_complexity: int | None = None,
    extra_effects: Iterable[EffectRequest] = (),
    allow_incomplete: bool = False,
) -> AssembledModel:
    """Assemble the simulation model of building model ``model_name`` loaded in ``store``.

    :raises AssemblyError: a signature names a class no loaded ontology declares, or no signature
        matches anything in the model.
    :raises IncompleteModelError: an input has no source (unless ``allow_incomplete``; the
        problems are then listed in ``notes`` and the input left unconnected).
    """
    library = dict(library) if library is not None else SignatureLibrary.load()
    dataset = store.matching_dataset(model_name)
    problems = [p for sig in library.values() for p in missing_class_report(store, sig, dataset)]
    if problems:
        raise AssemblyError("\n".join(problems))

    notes: list[str] = []
    components = [s for s in library.values() if s.kind == "component"]
    if max_complexity is not None:
        components = [s for s in components if s.complexity <= max_complexity]
    depth = _class_depth(store, dataset)
    session = MatchSession(store, dataset)  # the graph does not change while assembling
    candidates = []
    with cyclic_gc_paused():  # one collection after the library, not one per signature
        for signature in components:
            for match in best_match_per_anchor(match_signature(store, signature, session=session), signature, notes):
                candidates.append((signature, match))
    candidates.sort(key=lambda c: (
        -sum(depth(cls) for node in c[0].modeled_nodes for cls in c[0].nodes[node].classes),
        -c[0].complexity, -len(c[0].modeled_nodes), c[0].id, modeled_nodes(c[0], c[1]),
    ))
    chosen: list[tuple[Signature, MatchValues]] = []
    claimed: dict[str, tuple[Signature, str]] = {}  # building node → the signature representing it, its anchor
    lost: dict[tuple[str, str], str] = {}  # (signature id, its anchor node) → why it was not used there
    for signature, match in candidates:
        nodes = modeled_nodes(signature, match)
        taken = [n for n in nodes if n in claimed]
        if taken:
            winner, at = claimed[taken[0]]
            why = (f"signature {winner.id} chosen over {signature.id} ({_why(winner, signature, depth)})"
                   if winner.id != signature.id else f"the {winner.id} at {short_name(at)} represents it already")
            notes.append(f"{short_name(taken[0])}: {why}")
            lost.setdefault((signature.id, nodes[0]), f"{signature.id} matches there but also needs {taken[0]}: {why}")
            continue
        chosen.append((signature, match))
        for node in nodes:
            claimed[node] = (signature, nodes[0])
    if not chosen:
        raise AssemblyError(f"no signature of the library matches anything in model {model_name}: it holds no device "
                            "typed with a class the signatures know (SAREF4BLDG, FSO, graphtwin's own, or Brick through "
                            "the alignment; graphtwin brick-report lists what a Brick model lacks)")
    anchors = defaultdict(list)
    for signature, match in chosen:
        anchors[signature.id].append(modeled_nodes(signature, match)[0])
    node_names = {signature_id: distinct_local_names(nodes) for signature_id, nodes in anchors.items()}
    instances: dict[str, ComponentInstance] = {}
    for signature, match in chosen:
        node_name = node_names[signature.id][modeled_nodes(signature, match)[0]]
        instance = instantiate(store, model_name, signature, match, node_name=node_name)
        instances[instance.iri] = instance

    notes += [f"{short_name(modeled_nodes(s, match)[0])}: {s.note}" for s, match in chosen if s.note]
    notes += _values_without_unit(store, instances, session)
    notes += [note for i in instances.values() if i.measurement is not None for note in _unit_notes(i)]
    misspelt = misspelt_terms(store, model_name)  # a misspelt term is often why a pattern misses
    notes += misspelt.notes
    effect_requests = list(extra_effects) + recorded_effects(store, model_name, library)
    connections, unconnected = wire(instances)
    for request in effect_requests:
        connections = splice_effect(store, model_name, request, library=library, instances=instances,
                                    connections=connections, session=session)
    # measuring devices without a modelled source are boundary inputs, not missing connections
    devices = {iri for iri, inst in instances.items() if issubclass(inst.model_class, MeasuringDevice)}
    incomplete = misspelt.dropped + [u.reason for u in unconnected if u.component not in devices]
    fed, read = {c.target for c in connections}, {c.source for c in connections}
    unread = sorted(i for i in devices if i not in fed and i not in read)  # a column nothing needs
    left_out = "left out, its column is not needed"
    no_target = {u.component: f"{u.reason}: {instances[u.component].node} " + (
        f"cannot be a calibration target and no component reads it: {left_out}" if u.component in unread
        else "is a boundary input, not a calibration target") for u in unconnected
        if u.component in devices and u.source_modelled}
    notes += list(no_target.values())
    incomplete += _unmatched_anchor_report(store, components, claimed=claimed, lost=lost, session=session)
    if incomplete and not allow_incomplete:
        raise IncompleteModelError(incomplete, notes=notes)
    notes.extend(incomplete)

    notes += [f"{short_name(instances[i].node)}: measured, but no component reads it (what it drives or sets is not "
              f"in the model): {left_out}" for i in unread if i not in no_target]
    instances = {iri: instance for iri, instance in instances.items() if iri not in unread}
    devices -= set(unread)
    boundary = tuple(sorted(i for i in devices if i not in fed))
    targets = tuple(sorted(i for i in devices if i in fed))
    notes += _coil_outlet_notes(store, model_name, instances, connections)
    mapped, estimated = split_parameters(instances, measured_outputs(connections, instances, targets),
                                         connections)
    notes += [f"{problem}: a calibration refuses it; fix the value (or its unit) in the model graph"
              for problem in mapped_values_outside_bounds(mapped, instances)]
    return AssembledModel(
        components=dict(sorted(instances.items())), connections=tuple(sorted(connections, key=dataclasses.astuple)),
        boundary_inputs=boundary, targets=targets, mapped_parameters=mapped,
        estimated_parameters=estimated, building_graph=str(store.model_graph(model_name).value),
        notes=tuple(notes),
    )


def _coil_outlet_notes(store: GraphStore, model_name: str, instances: Mapping[str, ComponentInstance],
                       connections: Iterable[Connection]) -> list[str]:
    """A measuring device read as a water coil's outlet air where the coil's one node feeds more than
    one node: its water leaves by that node too, so the device may read the water (a return water
    sensor), which the coil model does not give. A coil is one node where its signature's valve
    supplies water to the node its outlet air leaves. One sentence each, naming how to say which."""
    notes = []
    for c in connections:
        coil, device = instances[c.source], instances[c.target]
        if c.source_port != "outlet_air_temperature" or not issubclass(device.model_class, MeasuringDevice):
            continue
        air_node = next(o.node for o in coil.signature.outputs if o.port == "outlet_air_temperature")
        if not any(t.subject == "valve" and t.object == air_node and t.predicate == FSO.iri("suppliesFluidTo")
                   for t in coil.signature.triples):
            continue
        fed = sorted({row["to"].value for row in store.run_named_query(
            "flow-edges", dataset=model_name, **{"from": ox.NamedNode(coil.node)}) if row["kind"].value == "fluid"})
        if len(fed) > 1:
            notes.append(
                f"{short_name(device.node)}: read as the outlet air of {short_name(coil.node)}, whose one node feeds "
                f"{len(fed)} nodes ({', '.join(map(short_name, fed))}): its water leaves there too. If "
                f"{short_name(device.node)} reads the water, which this coil model does not give, state it with "
                f"fso:returnsFluidTo instead of fso:suppliesFluidTo (it is then left out)")
    return notes


def _class_depth(store: GraphStore, dataset: list[ox.NamedNode]) -> ClassDepth:
    """Class IRI → how many superclasses it has in ``dataset`` (cached): the specificity of a class."""
    cache: dict[str, int] = {}
    query = "SELECT ?class (COUNT(DISTINCT ?super) AS ?n) WHERE { ?class <%s>+ ?super } GROUP BY ?class" % RDFS.subClassOf.value

    def depth(class_iri: str) -> int:
        if class_iri not in cache:
            rows = store.query(query, substitutions={"class": ox.NamedNode(class_iri)}, default_graph=dataset)
            cache[class_iri] = int(rows[0]["n"].value) if rows else 0
        return cache[class_iri]

    return depth


def _why(winner: Signature, loser: Signature, depth: ClassDepth) -> str:
    """Why ``winner`` claims a node before ``loser``, in words (the order of :func:`assemble`)."""
    win = sum(depth(c) for n in winner.modeled_nodes for c in winner.nodes[n].classes)
    lose = sum(depth(c) for n in loser.modeled_nodes for c in loser.nodes[n].classes)
    if win != lose:
        return f"more specific classes: depth {win} against {lose}"
    if winner.complexity != loser.complexity:
        return f"higher complexity {winner.complexity} against {loser.complexity}"
    if len(winner.modeled_nodes) != len(loser.modeled_nodes):
        return f"represents {len(winner.modeled_nodes)} nodes against {len(loser.modeled_nodes)}"
    return "first in identifier order"


def _values_without_unit(store: GraphStore, instances: Mapping[str, ComponentInstance], session: MatchSession) -> list[str]:
    """Parameters left to estimate although the graph states their value, without the unit its
    OPTIONAL block requires (a nominal power of 1800 with no ``saref:isMeasuredIn``): one sentence
    each. They are found by matching the block without its unit triples, made required — once per
    signature and parameter, whatever the number of components lacking the value."""
    lacking: dict[tuple[str, str], list[ComponentInstance]] = defaultdict(list)
    for instance in instances.values():
        for mapping in instance.signature.parameters:
            if mapping.unit_node is not None and mapping.node not in instance.bindings:
                lacking[(instance.signature.id, mapping.name)].append(instance)
    found: dict[tuple[str, str], str] = {}  # (component IRI, parameter) → the sentence
    for (_signature_id, name), lacking_it in lacking.items():
        signature = lacking_it[0].signature
        mapping = next(m for m in signature.parameters if m.name == name)
        anchor = signature.modeled_nodes[0]
        block = _optional_block(signature, mapping.node, through=anchor, without=mapping.unit_node)
        if not block:
            continue
        nodes = {n for t in block for n in (t.subject, t.object)} | {anchor}
        probe = dataclasses.replace(
            signature, id=f"{signature.id}:{mapping.name}:without-unit", modeled_nodes=(anchor,),
            nodes={n: signature.nodes[n] for n in nodes}, inputs=(), outputs=(), parameters=(), splice=None,
            triples=tuple(dataclasses.replace(t, rule=Rule.EXACT, optional=False) for t in block),
        )
        unit_triple = next(t for t in signature.triples if mapping.unit_node in (t.subject, t.object))
        holder_node = unit_triple.subject if unit_triple.object == mapping.unit_node else unit_triple.object
        first_match: dict[str, MatchValues] = {}
        for match in match_signature(store, probe, session=session):
            first_match.setdefault(match[anchor], match)
        for instance in lacking_it:
            match = first_match.get(instance.bindings[anchor])
            if match is not None:
                found[(instance.iri, name)] = (
                    f"{short_name(instance.node)}: parameter {mapping.name} of {signature.id} is estimated, not mapped: "
                    f"the graph gives {match[mapping.node]} but no unit for it "
                    f"(add <{match.get(holder_node)}> <{unit_triple.predicate}> <a QUDT unit IRI> .)")
    return [found[(iri, m.name)] for iri, instance in instances.items() for m in instance.signature.parameters
            if (iri, m.name) in found]


def _unit_notes(instance: ComponentInstance) -> list[str]:
    """What the column of a measured device will meet when read: no unit declared, a unit graphtwin
    does not know (with the one it resembles), or a unit of another dimension than the quantity the
    device's signature measures (a temperature sensor in percent): each column is refused then."""
    unit, name = instance.measurement.unit, short_name(instance.node)
    if unit is None:
        return [f"{name}: declares no unit (saref:isMeasuredIn, in Brick brick:hasUnit): its column cannot "
                f"be read (add <{instance.node}> saref:isMeasuredIn <a QUDT unit IRI> .)"]
    try:
        declared = unit_spec(unit)
    except UnitError:
        return [f"{name}: its unit {unit} is not a unit graphtwin knows{closest_unit_hint(unit)}: its column cannot "
                "be read"]
    quantity = instance.signature.output_quantity("measured_value")
    if quantity in QUANTITY_UNITS and declared.dimension != unit_spec(QUANTITY_UNITS[quantity]).dimension:
        return [f"{name}: its unit {unit} is a unit of {declared.dimension.replace('_', ' ')}, but the device "
                f"measures a {quantity.replace('_', ' ')}: its column cannot be read"]
    return []


def _optional_block(signature: Signature, node: str, *, through: str, without: str) -> list[PatternTriple]:
    """The optional triples connected to ``node``, not walking on through node ``through`` (the
    component's own node) and leaving out those that touch node ``without``."""
    optional = [t for t in signature.triples if t.rule is Rule.OPTIONAL and without not in (t.subject, t.object)]
    reached, frontier, block = {node}, [node], []
    while frontier:
        current = frontier.pop()
        for triple in optional:
            if current in (triple.subject, triple.object) and triple not in block:
                block.append(triple)
                other = triple.object if triple.subject == current else triple.subject
                if other not in reached and other != through:
                    reached.add(other)
                    frontier.append(other)
    return block


def _unmatched_anchor_report(
    store: GraphStore, components: Iterable[Signature], *, claimed: Mapping[str, tuple[Signature, str]],
    lost: Mapping[tuple[str, str], str], session: MatchSession,
) -> list[str]:
    """For building nodes of a signature's modelled class that no component represents: why that
    signature is not used there, as a sentence — it matched but lost a node it needs to another
    signature (``lost``), or the first of its required triples that finds nothing there. A node
    that a deeper partial match of the same signature already holds in another role (a coil's
    water side, found from its air side) gets no sentence of its own."""
    problems = []
    for signature in components:
        anchor = signature.modeled_nodes[0]
        instances = session.instances(signature.nodes[anchor].classes)
        found: dict[str, tuple[str, int, set[str]]] = {}
        for node in sorted(n.value for n in instances if isinstance(n, ox.NamedNode)):
            if node in claimed:
                continue
            if (signature.id, node) in lost:
                problems.append(f"{node} is not modelled: {lost[(signature.id, node)]}")
                continue
            missing = _first_failing_triple(store, signature, anchor=anchor, node=node, session=session)
            if missing is not None:
                found[node] = missing
        held = {other for node, (_, depth, bound) in found.items() if depth > 0 for other in bound - {node}}
        problems += [sentence for node, (sentence, depth, _) in found.items() if depth > 0 or node not in held]
    return sorted(set(problems))


def _first_failing_triple(store: GraphStore, signature: Signature, *, anchor: str, node: str,
                          session: MatchSession) -> tuple[str, int, set[str]] | None:
    """Why ``signature`` does not match at ``node`` (bound to ``anchor``): its required triples taken
    outward from the anchor, each joined to those before it, and the first after which nothing
    matches there, in words (a check valve missing downstream of a coil's water side is named as
    such, not as the coil's fault); with how many triples matched before it and the nodes they
    bound in the signature's modelled roles. None when all of them match."""
    reached, taken, bound = {anchor}, [], {anchor: node}
    for step in required_outward(anchor, signature.triples):
        near = step.subject if step.subject in reached else step.object
        probe = dataclasses.replace(
            signature, nodes={n: signature.nodes[n] for n in reached | {step.subject, step.object}},
            triples=(*taken, step), modeled_nodes=(anchor,), inputs=(), outputs=(), parameters=(), splice=None,
        )
        hits = [m for m in match_signature(store, probe, session=session) if m.get(anchor) == node]
        if not hits:
            why = _describe_missing(step, signature, anchor=near, node=bound[near])
            held = {str(value) for role, value in bound.items() if role in signature.modeled_nodes}
            return f"{node} is not modelled by {signature.id}: {why}", len(taken), held
        taken.append(step)
        reached |= {step.subject, step.object}
        bound = {k: str(v) for k, v in hits[0].items() if k in reached}
    return None


def _describe_missing(triple: PatternTriple, signature: Signature, *, anchor: str, node: str) -> str:
    other = triple.object if triple.subject == anchor else triple.subject
    spec = signature.nodes[other]
    what = " or ".join(short_name(c) for c in spec.classes) or (spec.iri or "value")
    if triple.rule is Rule.TRAVERSE:
        sides = ("upstream", "downstream") if triple.object == anchor else ("downstream", "upstream")
        side = " or ".join(sides if triple.or_reverse else sides[:1])
        stops = "".join(f"{short_name(c)} instances, " for c in triple.stop_at)
        return (f"no {what} {side} of {node} along {triple.predicate} (the search stops at {stops}building spaces, "
                f"boilers, chillers and cooling towers; signature {signature.file_name})")
    if triple.subject == anchor:
        return (f"no triple <{node}> <{triple.predicate}> ?{other} with ?{other} a {what} "
                f"(signature {signature.file_name})")
    return f"no triple ?{other} <{triple.predicate}> <{node}> with ?{other} a {what} (signature {signature.file_name})"
