"""Model assembly: match every signature in the building graph, instantiate and wire the components.

The paper's Sec. 3.3 (Bjørnskov, Jradi & Wetter): each signature is matched; every match becomes a
component instance representing the building nodes the signature models; each input is connected by
intersecting its source node with the nodes other components model, and taking the output that
carries the wanted quantity at that node. Then

* boundary inputs = measuring devices with no connected input (their measured series drive the model),
* calibration targets = measuring devices with exactly one connected input (Eq. 1),
* parameters to estimate = all parameters − those mapped from the graph (Eq. 2).

When several signatures claim the same building node, the choice is deterministic and explained in
``AssembledModel.notes``: a signature whose modelled nodes carry more specific classes wins (class
depth in the loaded ontology), then the higher ``complexity`` not above the user's cap, then the
signature covering more nodes, then the id.

Effects (``kind = "effect"`` signatures) are only instantiated where the building graph records them
(``node gt:hasEffect [ gt:effectSignature <signature IRI> ]``) or where the caller asks for them
(``extra_effects``, used by the diagnosis to try candidates without touching the graph). An effect is
spliced into one port of the component that represents its ``splice.node``.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import pyoxigraph as ox

from service.errors import AssemblyError, IncompleteModelError
from service.model.assembled_model import (
    AssembledModel, ComponentInstance, Connection, MeasurementLink, ParameterRef,
    mapped_values_outside_bounds,
)
from service.runtime import cyclic_gc_paused
from service.components.measuring_device import MeasuringDevice
from service.graph.namespaces import BRICK, GTR, OWL, RDF, RDFS, distinct_local_names, local_name, namespace_of
from service.components.library import SignatureLibrary, host_ports, load_model_class
from service.matching.signature import PatternTriple, Rule, Signature
from service.matching.matcher import MatchSession, match_signature, missing_class_report
from service.graph.store import ONTOLOGY_GRAPH, GraphStore
from service.graph.units import convert

__all__ = ["AssemblyError", "IncompleteModelError", "assemble", "EffectRequest", "component_iri", "without_model",
           "recorded_effects"]


@dataclass(frozen=True)
class EffectRequest:
    """Add effect signature ``effect`` at building node ``node`` (its splice node binds to it)."""

    effect: str
    node: str


def component_iri(model_name: str, signature: Signature, node_name: str) -> str:
    """Stable IRI of a component instance: model name, signature id and the name of the node it
    represents — its local name, hashed (:func:`~service.graph.namespaces.distinct_local_names`) where
    other nodes the same signature represents share it (``…/unit1/supply_fan``,
    ``…/unit2/supply_fan``), so no instance replaces another."""
    return f"{GTR}model/{model_name}/component/{signature.id}/{node_name}"


def without_model(key: str) -> str:
    """A component IRI or parameter key without its model: ``…/model/NAME/component/Fan/supply_fan#c1``
    → ``Fan/supply_fan#c1``, the same for every name (or version) the building model is loaded under."""
    return key.rsplit("/component/", 1)[-1]


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
            for match in _best_match_per_anchor(match_signature(store, signature, session=session), signature, notes):
                candidates.append((signature, match))
    candidates.sort(key=lambda c: (
        -sum(depth(cls) for node in c[0].modeled_nodes for cls in c[0].nodes[node].classes),
        -c[0].complexity, -len(c[0].modeled_nodes), c[0].id, _modeled(c[0], c[1]),
    ))
    chosen: list[tuple[Signature, Mapping[str, str | None]]] = []
    claimed: dict[str, tuple[Signature, str]] = {}  # building node → the signature representing it, its anchor
    lost: dict[tuple[str, str], str] = {}  # (signature id, its anchor node) → why it was not used there
    for signature, match in candidates:
        nodes = _modeled(signature, match)
        taken = [n for n in nodes if n in claimed]
        if taken:
            winner, at = claimed[taken[0]]
            why = (f"signature {winner.id} chosen over {signature.id} ({_why(winner, signature, depth)})"
                   if winner.id != signature.id else f"the {winner.id} at {_short(at)} represents it already")
            notes.append(f"{_short(taken[0])}: {why}")
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
        anchors[signature.id].append(_modeled(signature, match)[0])
    node_names = {signature_id: distinct_local_names(nodes) for signature_id, nodes in anchors.items()}
    instances: dict[str, ComponentInstance] = {}
    for signature, match in chosen:
        instance = _instantiate(store, model_name, signature, match, node_names[signature.id][_modeled(signature, match)[0]])
        instances[instance.iri] = instance

    notes += _values_without_unit(store, instances, session)
    notes += _undeclared_class_notes(store, model_name)
    effect_requests = list(extra_effects) + recorded_effects(store, model_name, library)
    connections, unconnected = _wire(instances)
    for request in effect_requests:
        connections = _splice_effect(store, model_name, library, request, instances, connections, session)
    # measuring devices without a modelled source are boundary inputs, not missing connections
    devices = {iri for iri, inst in instances.items() if issubclass(inst.model_class, MeasuringDevice)}
    incomplete = [p for iri, p, _ in unconnected if iri not in devices]
    notes += [f"{p}: {instances[iri].node} is a boundary input, not a calibration target"
              for iri, p, source_modelled in unconnected if iri in devices and source_modelled]
    incomplete += _unmatched_anchor_report(store, components, claimed, lost, session)
    if incomplete and not allow_incomplete:
        raise IncompleteModelError(incomplete)
    notes.extend(incomplete)

    fed = {c.target for c in connections}
    boundary = tuple(sorted(i for i in devices if i not in fed))
    read = {c.source for c in connections}
    notes += [f"{_short(instances[i].node)}: measured, but no component reads it (what it drives or sets is not "
              f"in the model)" for i in boundary if i not in read]
    targets = tuple(sorted(i for i in devices if i in fed))
    mapped, estimated = _parameters(instances)
    notes += [f"{problem}: a calibration refuses it; fix the value (or its unit) in the model graph"
              for problem in mapped_values_outside_bounds(mapped, instances)]
    return AssembledModel(
        components=dict(sorted(instances.items())), connections=tuple(sorted(connections, key=dataclasses.astuple)),
        boundary_inputs=boundary, targets=targets, mapped_parameters=mapped,
        estimated_parameters=estimated, building_graph=str(store.model_graph(model_name).value),
        notes=tuple(notes),
    )


def _modeled(signature: Signature, match: Mapping[str, str | None]) -> tuple[str, ...]:
    return tuple(str(match[n]) for n in signature.modeled_nodes)


def _best_match_per_anchor(matches: Sequence[Mapping[str, str | None]], signature: Signature,
                           notes: list[str] | None = None):
    """One match per modelled-node tuple: the one binding most optional nodes, then the first in
    sorted order (several matches arise when, e.g., two sensors sit on parallel upstream branches,
    or a coil and a bypass both lie nearest upstream of a fan); a tie is said in ``notes``."""
    best: dict[tuple[str, ...], Mapping[str, str | None]] = {}
    most_bound: dict[tuple[str, ...], int] = {}
    tied: dict[tuple[str, ...], list[Mapping[str, str | None]]] = {}
    for match in matches:  # sorted: the first of a tie is kept
        key = _modeled(signature, match)
        bound = sum(v is not None for v in match.values())
        if bound > most_bound.get(key, -1):
            best[key], most_bound[key], tied[key] = match, bound, []
        elif bound == most_bound[key]:
            tied[key].append(match)
    for key in sorted(k for k, others in tied.items() if others and notes is not None):
        kept = best[key]
        differing = sorted({n for other in tied[key] for n, v in other.items() if v != kept[n]})
        alternatives = "; ".join(", ".join(f"{n} = {_short(str(other[n]))}" for n in differing) for other in tied[key])
        notes.append(f"{_short(key[0])}: {signature.id} matches {len(tied[key]) + 1} ways alike; kept "
                     f"{', '.join(f'{n} = {_short(str(kept[n]))}' for n in differing)} (first in IRI order) "
                     f"over {alternatives}: a more specific graph (or a sensor on the branch) would decide")
    return [best[k] for k in sorted(best)]


def _class_depth(store: GraphStore, dataset: list[ox.NamedNode]):
    cache: dict[str, int] = {}
    query = "SELECT ?class (COUNT(DISTINCT ?super) AS ?n) WHERE { ?class <%s>+ ?super } GROUP BY ?class" % RDFS.subClassOf.value

    def depth(class_iri: str) -> int:
        if class_iri not in cache:
            rows = store.query(query, substitutions={"class": ox.NamedNode(class_iri)}, default_graph=dataset)
            cache[class_iri] = int(rows[0]["n"].value) if rows else 0
        return cache[class_iri]

    return depth


def _why(winner: Signature, loser: Signature, depth) -> str:
    win = sum(depth(c) for n in winner.modeled_nodes for c in winner.nodes[n].classes)
    lose = sum(depth(c) for n in loser.modeled_nodes for c in loser.nodes[n].classes)
    if win != lose:
        return f"more specific classes: depth {win} against {lose}"
    if winner.complexity != loser.complexity:
        return f"higher complexity {winner.complexity} against {loser.complexity}"
    if len(winner.modeled_nodes) != len(loser.modeled_nodes):
        return f"represents {len(winner.modeled_nodes)} nodes against {len(loser.modeled_nodes)}"
    return "first in identifier order"


def _short(iri: str) -> str:
    return iri.replace("#", "/").rsplit("/", 1)[-1]


def _instantiate(store: GraphStore, model_name: str, signature: Signature, match: Mapping[str, str | None],
                 node_name: str) -> ComponentInstance:
    model_class = load_model_class(signature)
    nodes = _modeled(signature, match)
    mapped: dict[str, float] = {}
    for mapping in signature.parameters:
        raw = match.get(mapping.node)
        if raw is None:
            continue
        spec = model_class.parameter(mapping.name)
        try:
            value = float(raw)
        except ValueError:
            raise AssemblyError(
                f"{nodes[0]}: parameter {mapping.name} of {signature.id} maps to {raw!r}, which is not a number"
            ) from None
        unit = match.get(mapping.unit_node) if mapping.unit_node else None
        if unit is not None:
            value = float(convert([value], unit, spec.unit)[0])
        mapped[mapping.name] = value
    measurement = None
    if issubclass(model_class, MeasuringDevice):
        measurement = _measurement_link(store, model_name, nodes[0])
    return ComponentInstance(
        iri=component_iri(model_name, signature, node_name), signature=signature,
        bindings={k: v for k, v in match.items() if v is not None}, modeled_nodes=nodes,
        mapped_parameters=mapped, measurement=measurement,
    )


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
        first_match: dict[str, Mapping[str, str | None]] = {}
        for match in match_signature(store, probe, session=session):
            first_match.setdefault(match[anchor], match)
        for instance in lacking_it:
            match = first_match.get(instance.bindings[anchor])
            if match is not None:
                found[(instance.iri, name)] = (
                    f"{_short(instance.node)}: parameter {mapping.name} of {signature.id} is estimated, not mapped: "
                    f"the graph gives {match[mapping.node]} but no unit for it "
                    f"(add <{match.get(holder_node)}> <{unit_triple.predicate}> <a QUDT unit IRI> .)")
    return [found[(iri, m.name)] for iri, instance in instances.items() for m in instance.signature.parameters
            if (iri, m.name) in found]


def _undeclared_class_notes(store: GraphStore, model_name: str) -> list[str]:
    """One sentence per class that no loaded ontology declares and that is all a signature could see
    of the nodes it types (``queries/undeclared-classes.rq``), with the declared class its name is
    closest to when one is close (a misspelling): those nodes are in no component."""
    rows = store.run_named_query("undeclared-classes", **store.graph_variables(model_name))
    undeclared = [(row["class"].value, int(row["nodes"].value), row["first_node"].value) for row in rows]
    if not undeclared:
        return []
    declared = defaultdict(list)  # namespace → the local names of the classes the ontologies declare in it
    for t in store.graph_triples(ONTOLOGY_GRAPH):
        if t.predicate == RDF.type and t.object in (OWL.Class, RDFS.Class) and isinstance(t.subject, ox.NamedNode):
            declared[namespace_of(t.subject.value)].append(local_name(t.subject.value))
    notes = []
    for cls, count, first in undeclared:
        nodes = first if count == 1 else f"{count} nodes, e.g. {first}"
        if namespace_of(cls) == BRICK:  # official Brick classes outside graphtwin's subset are no misspelling
            hint = " (graphtwin brick-report says what the Brick alignment needs)"
        else:
            close = difflib.get_close_matches(local_name(cls), declared[namespace_of(cls)], n=1, cutoff=0.85)
            hint = f" (did you mean {namespace_of(cls)}{close[0]}?)" if close else ""
        notes.append(f"{_short(first)}: its class {cls} ({nodes}) is declared by no loaded ontology, and the node has "
                     f"no other type a signature matches: no component models it{hint}")
    return notes


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


def _measurement_link(store: GraphStore, model_name: str, node: str) -> MeasurementLink:
    rows = store.run_named_query("measurement-link", dataset=model_name, device=ox.NamedNode(node))
    series_id = unit = None
    if rows:
        series_id = rows[0]["series_id"].value if rows[0].get("series_id") is not None else None
        unit = rows[0]["unit"].value if rows[0].get("unit") is not None else None
    return MeasurementLink(node=node, series_id=series_id, unit=unit)


def _outputs_at(instance: ComponentInstance) -> dict[tuple[str, str], str]:
    """(building node IRI, quantity) → output port of ``instance``."""
    table = {}
    for output in instance.signature.outputs:
        node = instance.bindings.get(output.node)
        if node is not None:
            table[(node, output.quantity)] = output.port
    return table


def _wire(instances: Mapping[str, ComponentInstance]) -> tuple[list[Connection], list[tuple[str, str, bool]]]:
    """The connections, and the inputs left unconnected: (component IRI, why in words, whether
    the input's source node is modelled — by a component without an output of that quantity)."""
    providers: dict[tuple[str, str], list[tuple[str, str]]] = defaultdict(list)
    for iri, instance in instances.items():
        for key, port in _outputs_at(instance).items():
            providers[key].append((iri, port))
    connections: list[Connection] = []
    unconnected: list[tuple[str, str, bool]] = []
    for iri, instance in instances.items():
        for mapping in instance.signature.inputs:
            source_node = instance.bindings.get(mapping.source)
            where = f"input {mapping.port} of {instance.signature.id} at {instance.node}"
            if source_node is None:
                unconnected.append((iri, f"{where}: no {mapping.source} node matched, so nothing feeds it", False))
                continue
            found = [p for p in providers.get((source_node, mapping.quantity), []) if p[0] != iri]
            if not found:
                modelled_by = [i.signature.id for i in instances.values() if source_node in i.modeled_nodes]
                reason = (
                    f"{source_node} is modelled by {', '.join(modelled_by)}, which has no output carrying "
                    f"'{mapping.quantity}' there" if modelled_by else f"no component models {source_node}"
                )
                unconnected.append((iri, f"{where}: {reason}", bool(modelled_by)))
                continue
            source, port = sorted(found)[0]
            connections.append(Connection(source, port, iri, mapping.port))
    return connections, unconnected


def recorded_effects(store: GraphStore, model_name: str, library: Mapping[str, Signature]) -> list[EffectRequest]:
    """The effects building model ``model_name`` records (``queries/applied-effects.rq``), sorted.

    :raises AssemblyError: one names an effect signature the library does not hold.
    """
    by_iri = {sig.iri: sig.id for sig in library.values() if sig.kind == "effect"}
    requests = []
    for row in store.run_named_query("applied-effects", dataset=model_name):
        signature_iri = row["effect_signature"].value
        if signature_iri not in by_iri:
            raise AssemblyError(
                f"{row['node'].value} records effect {signature_iri}, which is not in the signature library"
            )
        requests.append(EffectRequest(by_iri[signature_iri], row["node"].value))
    return sorted(set(requests), key=lambda r: (r.node, r.effect))


def _splice_effect(store, model_name, library, request, instances, connections, session) -> list[Connection]:
    signature = library.get(request.effect)
    if signature is None or signature.kind != "effect" or signature.splice is None:
        raise AssemblyError(f"{request.effect!r} is not an effect signature in the library")
    matches = [m for m in match_signature(store, signature, session=session)
               if m.get(signature.splice.node) == request.node]
    if not matches:
        dataset = store.matching_dataset(model_name)
        if not _is_node(store, request.node, dataset):
            named = sorted({row["x"].value for row in store.query(
                "SELECT DISTINCT ?x WHERE { ?x ?p ?o FILTER(isIRI(?x) && REGEX(STR(?x), CONCAT('[/#]', ?local, '$'))) }",
                substitutions={"local": ox.Literal(re.escape(request.node))}, default_graph=dataset)})
            hint = f": give its full IRI, e.g. {named[0]}" if named else ""
            raise AssemblyError(f"effect {signature.id} at {request.node}: the model has no node {request.node}{hint}")
        raise AssemblyError(
            f"effect {signature.id} does not apply at {request.node}: its pattern "
            f"({signature.source_file}) does not match there"
        )
    match = _best_match_per_anchor(matches, signature)[0]
    host = next((i for i in instances.values() if request.node in i.modeled_nodes), None)
    if host is None:
        raise AssemblyError(f"effect {signature.id} at {request.node}: no component models that node")
    if signature.splice.host_models and host.signature.model not in signature.splice.host_models:
        raise AssemblyError(
            f"effect {signature.id} at {request.node}: it extends {', '.join(signature.splice.host_models)}, "
            f"but {request.node} is modelled by {host.signature.model}"
        )
    ports = host_ports(signature, host.model_class)
    if signature.splice.port not in ports:
        raise AssemblyError(
            f"effect {signature.id} at {request.node}: it splices {signature.splice.side} {signature.splice.port!r}, "
            f"which {host.signature.model} (modelling {request.node}) does not have; its {signature.splice.side}s: "
            f"{', '.join(ports)} ({signature.source_file})"
        )
    effect = _instantiate(store, model_name, signature, match, local_name(_modeled(signature, match)[0]))
    effect = dataclasses.replace(effect, iri=f"{effect.iri}/on/{_short(host.iri)}")
    instances[effect.iri] = effect
    port = signature.splice.port
    spliced: list[Connection] = []
    if signature.splice.side == "output":
        for c in connections:
            spliced.append(dataclasses.replace(c, source=effect.iri, source_port="value_out")
                           if (c.source, c.source_port) == (host.iri, port) else c)
        spliced.append(Connection(host.iri, port, effect.iri, "value_in"))
    else:
        feeding = [c for c in connections if (c.target, c.target_port) == (host.iri, port)]
        if not feeding:
            raise AssemblyError(f"effect {signature.id} splices input {port} of {host.iri}, which nothing feeds")
        for c in connections:
            spliced.append(dataclasses.replace(c, target=effect.iri, target_port="value_in") if c in feeding else c)
        spliced.append(Connection(effect.iri, "value_out", host.iri, port))
    extra, missing = _wire({**{effect.iri: effect}, **{k: v for k, v in instances.items() if k != effect.iri}})
    spliced.extend(c for c in extra if c.target == effect.iri and c.target_port != "value_in")
    missing_here = [p for iri, p, _ in missing if iri == effect.iri and "value_in" not in p]
    if missing_here:
        raise IncompleteModelError(missing_here)
    return spliced


def _is_node(store: GraphStore, text: str, dataset: list[ox.NamedNode]) -> bool:
    """Whether ``text`` is the IRI of a subject of the model (``supply_fan`` alone is no IRI)."""
    try:
        node = ox.NamedNode(text)
    except ValueError:
        return False
    return bool(store.query("ASK { ?node ?p ?o }", substitutions={"node": node}, default_graph=dataset))


def _unmatched_anchor_report(store, components, claimed, lost: Mapping[tuple[str, str], str],
                             session: MatchSession) -> list[str]:
    """For building nodes of a signature's modelled class that no component represents: why that
    signature is not used there, as a sentence — it matched but lost a node it needs to another
    signature (``lost``), or the first of its required triples that finds nothing there."""
    problems = []
    for signature in components:
        anchor = signature.modeled_nodes[0]
        instances = session.instances(signature.nodes[anchor].classes)
        for node in sorted(n.value for n in instances if isinstance(n, ox.NamedNode)):
            if node in claimed:
                continue
            if (signature.id, node) in lost:
                problems.append(f"{node} is not modelled: {lost[(signature.id, node)]}")
                continue
            missing = _first_failing_triple(store, signature, anchor, node, session)
            if missing is not None:
                problems.append(missing)
    return sorted(set(problems))


def _first_failing_triple(store, signature: Signature, anchor: str, node: str, session: MatchSession) -> str | None:
    required = [t for t in signature.triples if t.rule is not Rule.OPTIONAL and anchor in (t.subject, t.object)]
    for triple in required:
        other = triple.object if triple.subject == anchor else triple.subject
        probe = dataclasses.replace(
            signature, nodes={anchor: signature.nodes[anchor], other: signature.nodes[other]},
            triples=(triple,), modeled_nodes=(anchor,), inputs=(), outputs=(), parameters=(), splice=None,
        )
        hits = [m for m in match_signature(store, probe, session=session) if m.get(anchor) == node]
        if not hits:
            return f"{node} is not modelled by {signature.id}: {_describe_missing(triple, anchor, signature, node)}"
    return None


def _describe_missing(triple: PatternTriple, anchor: str, signature: Signature, node: str) -> str:
    other = triple.object if triple.subject == anchor else triple.subject
    spec = signature.nodes[other]
    what = " or ".join(_short(c) for c in spec.classes) or (spec.iri or "value")
    if triple.rule is Rule.TRAVERSE:
        sides = ("upstream", "downstream") if triple.object == anchor else ("downstream", "upstream")
        side = " or ".join(sides if triple.or_reverse else sides[:1])
        stops = "".join(f"{_short(c)} instances, " for c in triple.stop_at)
        return (f"no {what} {side} of {node} along {triple.predicate} (the search stops at {stops}building spaces, "
                f"boilers, chillers and cooling towers; signature {signature.source_file})")
    if triple.subject == anchor:
        return f"no triple <{node}> <{triple.predicate}> ?{other} with ?{other} a {what} (signature {signature.source_file})"
    return f"no triple ?{other} <{triple.predicate}> <{node}> with ?{other} a {what} (signature {signature.source_file})"


def _parameters(instances: Mapping[str, ComponentInstance]) -> tuple[tuple[ParameterRef, ...], tuple[ParameterRef, ...]]:
    mapped, estimated = [], []
    for iri, instance in sorted(instances.items()):
        for spec in instance.model_class.parameters:
            if spec.name in instance.mapped_parameters:
                mapped.append(ParameterRef(iri, spec, instance.mapped_parameters[spec.name]))
            else:
                estimated.append(ParameterRef(iri, spec))
    return tuple(mapped), tuple(estimated)
