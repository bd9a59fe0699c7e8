"""Effect splicing: an effect signature instantiated at a building node and spliced into one port.

Effects (``kind = "effect"`` signatures) are instantiated only where the building graph records them
(``node gt:hasEffect [ gt:effectSignature <signature IRI> ]``, :func:`recorded_effects`) or where the
caller asks (:class:`EffectRequest`). The effect enters the component that represents its
``splice.node`` on one port: on an output it takes the port's consumers (``port → value_in``,
``value_out → consumers``), on an input its feed (``feed → value_in``, ``value_out → port``); an
input splice that leaves readings unchanged also gives the host's outputs reporting that input
(a position feedback) the feed.
Details: ``docs/assembly.md``.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass

import pyoxigraph as ox

from service.components.library import host_ports
from service.errors import AssemblyError, IncompleteModelError
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.matching.matcher import MatchSession, match_signature
from service.matching.signature import Signature
from service.model.assembled_model import ComponentInstance, Connection
from service.model.wiring import best_match_per_anchor, instantiate, modeled_nodes, short_name, wire

__all__ = ["EffectRequest", "recorded_effects", "splice_effect"]


@dataclass(frozen=True)
class EffectRequest:
    """Add effect signature ``effect`` at building node ``node`` (its splice node binds to it)."""

    effect: str
    node: str


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


def splice_effect(
    store: GraphStore, model_name: str, request: EffectRequest, *, library: Mapping[str, Signature],
    instances: dict[str, ComponentInstance], connections: list[Connection], session: MatchSession,
) -> list[Connection]:
    """``connections`` with the effect ``request`` names spliced in; the effect's instance is added
    to ``instances``.

    :raises AssemblyError: not an effect of ``library``, no such node, the pattern does not match
        there, no component models the node, or its model lacks the splice port (or is not a host).
    :raises IncompleteModelError: an input of the effect other than ``value_in`` has no source.
    """
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
            f"({signature.file_name}) does not match there"
        )
    match = best_match_per_anchor(matches, signature)[0]
    host = next((i for i in instances.values() if request.node in i.modeled_nodes), None)
    if host is None:
        raise AssemblyError(f"effect {signature.id} at {request.node}: no component models that node")
    if signature.splice.host_models and host.signature.model not in signature.splice.host_models:
        raise AssemblyError(
            f"effect {signature.id} at {request.node}: it extends the component models "
            f"{', '.join(m.rsplit(':', 1)[-1] for m in signature.splice.host_models)}, "
            f"but {request.node} is modelled by {host.signature.model.rsplit(':', 1)[-1]}"
        )
    ports = host_ports(signature, host.model_class)
    if signature.splice.port not in ports:
        raise AssemblyError(
            f"effect {signature.id} at {request.node}: it splices {signature.splice.side} {signature.splice.port!r}, "
            f"which {host.signature.model} (modelling {request.node}) does not have; its {signature.splice.side}s: "
            f"{', '.join(ports)} ({signature.file_name})"
        )
    effect = instantiate(store, model_name, signature, match, node_name=local_name(modeled_nodes(signature, match)[0]))
    effect = dataclasses.replace(effect, iri=f"{effect.iri}/on/{short_name(host.iri)}")
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
        feed = feeding[0]
        reports = ({p.name for p in host.model_class.outputs if p.reports == port}
                   if signature.splice.readings_unchanged else set())
        for c in connections:
            if c in feeding:
                c = dataclasses.replace(c, target=effect.iri, target_port="value_in")
            elif c.source == host.iri and c.source_port in reports:
                c = dataclasses.replace(c, source=feed.source, source_port=feed.source_port)
            spliced.append(c)
        spliced.append(Connection(effect.iri, "value_out", host.iri, port))
    extra, missing = wire({**{effect.iri: effect}, **{k: v for k, v in instances.items() if k != effect.iri}})
    spliced.extend(c for c in extra if c.target == effect.iri and c.target_port != "value_in")
    missing_here = [u.reason for u in missing if u.component == effect.iri and "value_in" not in u.reason]
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
