"""Adding an effect to a model: checked once, then written as a file (CLI) or as a new model version
in the store (HTTP job, demo).

An added effect is data: the applied-effect triples (:mod:`service.model.effect_recording`) at the
target node. A version ``<model>+<effect>`` holds the model's triples plus those, with its own
inferred and assembly graphs; the model itself is not changed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pyoxigraph as ox

from service.components.library import SignatureLibrary
from service.errors import ConflictError, InputError
from service.graph.namespaces import GT
from service.graph.rdf_io import parse_rdf
from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.model.assembly_triples import assembly_iri, assembly_triples
from service.model.effect_recording import applied_effect_triples, record_effect_in_file
from service.model.effect_splicing import EffectRequest, recorded_effects
from service.workflows.requests import AddEffectRequest

__all__ = ["EffectVersion", "checked_effect_triples", "check_effect_version", "add_effect_version",
           "add_effect_to_file"]


@dataclass(frozen=True, kw_only=True)
class EffectVersion:
    """A model version written with an added effect."""

    version: str
    base_model: str
    effect: str
    target: str
    triples: int
    components: int

    def to_dict(self) -> dict:
        return {"model": self.version, "base_model": self.base_model, "effect": self.effect, "target": self.target,
                "triples": self.triples, "components": self.components}


def checked_effect_triples(store: GraphStore, model: str, effect: str, target: str,
                           library: SignatureLibrary) -> list[ox.Triple]:
    """The triples recording ``effect`` at ``target`` in ``model``, once checked that the catalog has
    the effect and that it applies there (the model assembles with it).

    :raises UnknownEffectError: no such effect; :raises InputError: ``effect`` names a drift the
        diagnosis found (a parameter changing, not an effect to add); :raises AssemblyError: it does not
        apply at ``target``.
    """
    from service.diagnosis.drift import drifting_parameter  # SciPy: not at the command line's start

    parameter = drifting_parameter(effect)
    if parameter is not None:
        raise InputError(
            f"{effect} is the diagnosis's finding that the parameter {parameter} changed during the test "
            "window, not an effect the model lacks: nothing to add. Look at the component for what changed "
            "(fouling, a new setting, a repair), and calibrate again on data from after the change "
            "(graphtwin calibrate --train FROM/TO)")
    signature = library.effect(effect)
    assemble(store, model, library=library, extra_effects=[EffectRequest(effect, target)])
    return applied_effect_triples(signature, target)


def check_effect_version(store: GraphStore, request: AddEffectRequest, library: SignatureLibrary) -> str:
    """The name of the version ``request`` writes, checked.

    :raises ConflictError: that version exists with other effects (the same effect at another node,
        say): it is not overwritten — give ``version`` to keep both.
    """
    version = store.check_name(request.version_name)
    if store.has_model(version):
        existing = recorded_effects(store, version, library)
        wanted = {*recorded_effects(store, request.model, library), EffectRequest(request.effect, request.target)}
        if set(existing) != wanted:
            recorded = "; ".join(f"{r.effect} at {r.node}" for r in existing) or "no effect"
            raise ConflictError(f"model {version} exists with {recorded}: it is not overwritten; "
                                "give 'version' (a new model name) to keep both")
    return version


def _graph_triples(store: GraphStore, graph: ox.NamedNode) -> list[ox.Triple]:
    """Every triple of ``graph`` as its store dumps it (blank-node labels kept)."""
    data = store.backend.dump(graph, ox.RdfFormat.N_TRIPLES)
    return parse_rdf(data, ox.RdfFormat.N_TRIPLES, str(graph)) if data else []


def add_effect_version(store: GraphStore, request: AddEffectRequest, library: SignatureLibrary, *,
                       report: Callable[[str], None] = lambda message: None) -> EffectVersion:
    """Write the version ``request`` names: the model's triples plus the applied-effect triples,
    aligned and assembled in a scratch in-memory store (the alignment reads the graph it derives
    from), then written with its ``inferred`` and ``assembly`` graphs.

    :raises UnknownEffectError, AssemblyError: as :func:`checked_effect_triples`;
    :raises ConflictError: as :func:`check_effect_version`.
    """
    report(f"checking that {request.effect} applies at {request.target}")
    added = checked_effect_triples(store, request.model, request.effect, request.target, library)
    version = check_effect_version(store, request, library)
    triples = _graph_triples(store, store.model_graph(request.model)) + added
    report(f"aligning and assembling {version}")
    scratch = GraphStore.embedded(None)
    scratch.load_model(version, ox.serialize(triples, format=ox.RdfFormat.N_TRIPLES), "nt", source_name=version)
    assembled = assemble(scratch, version, library=library)
    store.write_graph(store.model_graph(version), triples)
    store.write_graph(store.inferred_graph(version), _graph_triples(scratch, scratch.inferred_graph(version)))
    store.write_graph(store.assembly_graph(version), assembly_triples(assembled, version) + [
        ox.Triple(assembly_iri(version), GT.derivedFromModel, ox.Literal(request.model))])
    return EffectVersion(version=version, base_model=request.model, effect=request.effect, target=request.target,
                         triples=len(triples), components=len(assembled.components))


def add_effect_to_file(model_file: Path, output: Path, effect: str, target: str, library: SignatureLibrary) -> None:
    """Write ``model_file`` with ``effect`` recorded at ``target`` to ``output`` (its suffix's format).

    :raises InputError: the model records that effect there already; others as :func:`checked_effect_triples`.
    """
    check = GraphStore.embedded(None)
    check.load_model("check", model_file)
    added = checked_effect_triples(check, "check", effect, target, library)
    if added[0] in check.graph_triples(check.model_graph("check")):
        raise InputError(f"{effect} is recorded at {target} in {model_file} already: nothing to add")
    record_effect_in_file(model_file, output, added)
