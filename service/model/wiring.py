"""Component instances and their wiring: a signature match becomes a component, its inputs connections.

Bjørnskov, Jradi & Wetter, Sec. 3.3: every match is a :class:`ComponentInstance` representing the
building nodes its signature models, with the parameters the graph gives converted to the model's
unit; each input is connected by intersecting its source node with the nodes the other components
model and taking the output that carries the wanted quantity there. Parameters to estimate = all
parameters − those mapped from the graph (Eq. 2). Details: ``docs/assembly.md``.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import pyoxigraph as ox

from service.components.component import SplicedEffect
from service.components.library import load_model_class
from service.components.measuring_device import MeasuringDevice
from service.errors import AssemblyError
from service.graph.namespaces import GTR
from service.graph.store import GraphStore
from service.graph.units import convert
from service.matching.signature import Signature
from service.model.assembled_model import ComponentInstance, Connection, MeasurementLink, ParameterRef

__all__ = [
    "MatchValues", "UnconnectedInput", "component_iri", "without_model", "parameter_label", "short_name",
    "modeled_nodes", "best_match_per_anchor",
    "instantiate", "wire", "measured_outputs", "split_parameters",
]

#: A signature match: pattern node id → bound IRI or literal lexical form (None: an optional node left unbound).
MatchValues = Mapping[str, str | None]


@dataclass(frozen=True)
class UnconnectedInput:
    """An input :func:`wire` found no source for: its component, why in words (``input P of S at N:
    …``), and whether its source node is modelled (by a component without an output of that quantity)."""

    component: str
    reason: str
    source_modelled: bool


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


def parameter_label(key: str) -> str:
    """A parameter key as people read it, ``<node>.<name>``: ``…/component/Fan/supply_fan#c1`` →
    ``supply_fan.c1``; an effect's
    (``…/component/ValveLeakage/heating_valve/on/heating_coil_air_side#leakage_fraction``) names the
    node the effect is at, ``heating_valve.leakage_fraction``."""
    component, _, name = without_model(key).partition("#")
    parts = component.split("/")
    return f"{parts[1] if len(parts) > 1 else parts[0]}.{name}"


def short_name(iri: str) -> str:
    """The last segment of ``iri`` (after its last ``/`` or ``#``): a node's name in notes."""
    return iri.replace("#", "/").rsplit("/", 1)[-1]


def modeled_nodes(signature: Signature, match: MatchValues) -> tuple[str, ...]:
    """The building nodes ``match`` binds to the signature's modelled pattern nodes, in its order."""
    return tuple(str(match[n]) for n in signature.modeled_nodes)


def best_match_per_anchor(matches: Sequence[MatchValues], signature: Signature,
                          notes: list[str] | None = None) -> list[MatchValues]:
    """One match per modelled-node tuple: the one binding most optional nodes, then the first in
    sorted order (several matches arise when, e.g., two sensors sit on parallel upstream branches,
    or a coil and a bypass both lie nearest upstream of a fan); a tie is said in ``notes``."""
    best: dict[tuple[str, ...], MatchValues] = {}
    most_bound: dict[tuple[str, ...], int] = {}
    tied: dict[tuple[str, ...], list[MatchValues]] = {}
    for match in matches:  # sorted: the first of a tie is kept
        key = modeled_nodes(signature, match)
        bound = sum(v is not None for v in match.values())
        if bound > most_bound.get(key, -1):
            best[key], most_bound[key], tied[key] = match, bound, []
        elif bound == most_bound[key]:
            tied[key].append(match)
    for key in sorted(k for k, others in tied.items() if others and notes is not None):
        kept = best[key]
        differing = sorted({n for other in tied[key] for n, v in other.items() if v != kept[n]})
        alternatives = "; ".join(", ".join(f"{n} = {short_name(str(other[n]))}" for n in differing)
                                 for other in tied[key])
        notes.append(f"{short_name(key[0])}: {signature.id} matches {len(tied[key]) + 1} ways alike; kept "
                     f"{', '.join(f'{n} = {short_name(str(kept[n]))}' for n in differing)} (first in IRI order) "
                     f"over {alternatives}: a more specific graph (or a sensor on the branch) would decide")
    return [best[k] for k in sorted(best)]


def instantiate(store: GraphStore, model_name: str, signature: Signature, match: MatchValues, *,
                node_name: str) -> ComponentInstance:
    """The component ``match`` of ``signature`` makes, named after ``node_name`` (:func:`component_iri`):
    its mapped parameters in the model's units, and a measuring device's :class:`MeasurementLink`.

    :raises AssemblyError: a mapped parameter's value is not a number.
    """
    model_class = load_model_class(signature)
    nodes = modeled_nodes(signature, match)
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


def wire(instances: Mapping[str, ComponentInstance]) -> tuple[list[Connection], list[UnconnectedInput]]:
    """The connections between ``instances``, and the inputs left unconnected."""
    providers: dict[tuple[str, str], list[tuple[str, str]]] = defaultdict(list)
    for iri, instance in instances.items():
        for key, port in _outputs_at(instance).items():
            providers[key].append((iri, port))
    connections: list[Connection] = []
    unconnected: list[UnconnectedInput] = []
    for iri, instance in instances.items():
        for mapping in instance.signature.inputs:
            source_node = instance.bindings.get(mapping.source)
            where = f"input {mapping.port} of {instance.signature.id} at {instance.node}"
            if source_node is None:
                if mapping.port in instance.model_class.fallback_inputs():
                    continue  # its parameter stands in
                unconnected.append(UnconnectedInput(
                    iri, f"{where}: no {mapping.source} node matched, so nothing feeds it", source_modelled=False))
                continue
            found = [p for p in providers.get((source_node, mapping.quantity), []) if p[0] != iri]
            if not found:
                modelled_by = [i.signature.id for i in instances.values() if source_node in i.modeled_nodes]
                reason = (
                    f"{source_node} is modelled by {', '.join(modelled_by)}, which has no output carrying "
                    f"'{mapping.quantity}' there" if modelled_by else f"no component models {source_node}"
                )
                unconnected.append(UnconnectedInput(iri, f"{where}: {reason}", source_modelled=bool(modelled_by)))
                continue
            source, port = sorted(found)[0]
            connections.append(Connection(source, port, iri, mapping.port))
    return connections, unconnected


def measured_outputs(connections: Sequence[Connection], instances: Mapping[str, ComponentInstance],
                     targets: Sequence[str]) -> dict[str, frozenset[str]]:
    """Component IRI → the names of its outputs a calibration target reads, directly or through
    spliced effects (an effect's ``value_in`` → ``value_out``: a sensor offset spliced on a sensor's input)."""
    feeds = defaultdict(list)
    for c in connections:
        feeds[(c.source, c.source_port)].append((c.target, c.target_port))
    target_set = set(targets)

    def reaches_target(source: str, port: str, seen: frozenset[str] = frozenset()) -> bool:
        for target, target_port in feeds[(source, port)]:
            if target in target_set:
                return True
            spliced = issubclass(instances[target].model_class, SplicedEffect) and target_port == "value_in"
            if spliced and target not in seen and reaches_target(target, "value_out", seen | {target}):
                return True
        return False

    return {iri: frozenset(port for port in instance.model_class.output_names() if reaches_target(iri, port))
            for iri, instance in instances.items()}


def split_parameters(
    instances: Mapping[str, ComponentInstance], measured: Mapping[str, frozenset[str]],
    connections: Sequence[Connection],
) -> tuple[tuple[ParameterRef, ...], tuple[ParameterRef, ...]]:
    """(mapped, estimated): every parameter of ``instances`` with the value the graph maps to it, or
    the value its model fixes given its ``measured`` outputs
    (:meth:`~service.components.component.ComponentModel.parameters_fixed_by_measurement`), or
    without a value, to be estimated (Eq. 2); by component IRI, then in the model's parameter order.
    A parameter standing in for an input that ``connections`` feed is neither."""
    fed = defaultdict(set)
    for c in connections:
        fed[c.target].add(c.target_port)
    mapped, estimated = [], []
    for iri, instance in sorted(instances.items()):
        fixed = instance.model_class.parameters_fixed_by_measurement(measured[iri]) | instance.mapped_parameters
        replaced = {p for port, p in instance.model_class.fallback_inputs().items() if port in fed[iri]}
        for spec in instance.model_class.parameters:
            if spec.name in replaced:
                continue
            if spec.name in fixed:
                mapped.append(ParameterRef(iri, spec, fixed[spec.name]))
            else:
                estimated.append(ParameterRef(iri, spec))
    return tuple(mapped), tuple(estimated)
