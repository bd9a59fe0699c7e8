"""The signature library as triples, and the two queries it makes possible."""

import pyoxigraph as ox
import pytest
from case_study import EX

from service.components.library import SignatureLibrary, load_signature
from service.graph.namespaces import GT, RDF, S4BLDG
from service.graph.store import SIGNATURE_GRAPH, GraphStore
from service.matching.library_triples import (
    ensure_signature_library,
    library_triples,
    load_signature_library_into,
    signature_triples,
)
from service.matching.signature import signature_from_dict
from service.model.assembly import assemble
from service.model.assembly_triples import assembly_triples
from service.resources import signatures_dir

SIG = "https://w3id.org/graphtwin/resource/signature/"
LIBRARY = SignatureLibrary.load()


def _objects(triples, subject: str, predicate: ox.NamedNode) -> set[str]:
    return {t.object.value for t in triples if t.subject.value == subject and t.predicate == predicate}


def test_the_fan_signature_as_triples():
    triples = signature_triples(load_signature(signatures_dir() / "fan.toml"))
    fan = SIG + "Fan"
    assert _objects(triples, fan, RDF.type) == {GT.Signature.value}
    assert _objects(triples, fan, GT.modelClass) == {"service.components.fan:Fan"}
    assert _objects(triples, fan, GT.complexity) == {"1"}
    assert _objects(triples, fan, GT.sourceFile) == {"fan.toml"}
    assert len(_objects(triples, fan, GT.hasPatternNode)) == 11  # the [nodes] table of fan.toml
    assert _objects(triples, fan, GT.modelsNode) == {fan + "/node/fan"}
    assert _objects(triples, fan + "/node/fan", GT.allowedClass) == {S4BLDG.Fan.value}
    assert _objects(triples, fan + "/node/nominal_flow_kind", GT.fixedIri) == {S4BLDG.nominalAirFlowRate.value}
    assert GT.LiteralPatternNode.value in _objects(triples, fan + "/node/nominal_flow", RDF.type)
    assert GT.AnyTermPatternNode.value in _objects(triples, fan + "/node/nominal_flow_unit", RDF.type)
    # triple 0: flow_source -suppliesFluidTo-> fan, traverse, required; triple 2: optional
    assert _objects(triples, fan + "/triple/0", GT.rule) == {GT.Traverse.value}
    assert _objects(triples, fan + "/triple/0", GT.patternSubject) == {fan + "/node/flow_source"}
    assert _objects(triples, fan + "/triple/0", GT.mayBeAbsent) == set()
    assert _objects(triples, fan + "/triple/2", GT.rule) == {GT.Optional.value}
    assert _objects(triples, fan + "/triple/2", GT.mayBeAbsent) == {"true"}
    assert _objects(triples, fan + "/triple/0", GT.orReverse) == set()
    coil = SIG + "HeatingCoil"  # its fan: upstream, else downstream, not past a mixing box
    fan_triple = next(f"{coil}/triple/{i}" for i, t in enumerate(LIBRARY["HeatingCoil"].triples) if t.subject == "fan")
    coil_triples = signature_triples(LIBRARY["HeatingCoil"])
    assert _objects(coil_triples, fan_triple, GT.orReverse) == {"true"}
    assert _objects(coil_triples, fan_triple, GT.stopsAt) == {GT.MixingBox.value}
    assert _objects(triples, fan + "/input/air_volume_flow", GT.sourceNode) == {fan + "/node/flow_source"}
    assert _objects(triples, fan + "/input/air_volume_flow", GT.quantity) == {"volume_flow"}
    assert _objects(triples, fan + "/output/electric_power", GT.atNode) == {fan + "/node/fan"}
    assert _objects(triples, fan + "/parameter/nominal_air_flow", GT.valueNode) == {fan + "/node/nominal_flow"}
    assert _objects(triples, fan + "/parameter/nominal_air_flow", GT.unitNode) == {fan + "/node/nominal_flow_unit"}


def test_an_effect_signature_says_where_it_is_spliced():
    triples = signature_triples(LIBRARY["CoilThermalMass"])
    effect = SIG + "CoilThermalMass"
    assert _objects(triples, effect, RDF.type) == {GT.EffectSignature.value}
    assert _objects(triples, effect, GT.spliceNode) == {effect + "/node/coil"}
    assert _objects(triples, effect, GT.splicePort) == {"outlet_air_temperature"}
    assert _objects(triples, effect, GT.spliceSide) == {"output"}
    assert _objects(triples, effect, GT.hostModel) == set(LIBRARY["CoilThermalMass"].splice.host_models)
    assert _objects(triples, effect, GT.sourceFile) == {"effects/coil_thermal_mass.toml"}
    assert _objects(triples, effect, GT.canAppear) == {"false"}  # a coil's mass is a property, not a fault
    assert _objects(signature_triples(LIBRARY["ValveLeakage"]), SIG + "ValveLeakage", GT.canAppear) == {"true"}


def test_every_signature_of_the_library_is_described_whole():
    triples = library_triples(LIBRARY)
    assert not any(isinstance(term, ox.BlankNode) for t in triples for term in (t.subject, t.object))
    assert len(set(triples)) == len(triples)
    for signature in LIBRARY.values():
        described = [t for t in triples if t.subject.value == signature.iri]
        assert len({t.object for t in described if t.predicate == GT.hasPatternNode}) == len(signature.nodes), signature.id
        assert len({t.object for t in described if t.predicate == GT.hasPatternTriple}) == len(signature.triples), signature.id
        assert len({t.object for t in described if t.predicate == GT.hasParameterMapping}) == len(signature.parameters), signature.id


def test_ensure_signature_library_writes_only_when_the_library_changed():
    store = GraphStore.embedded(None)
    assert ensure_signature_library(store, LIBRARY) is True
    assert ensure_signature_library(store, LIBRARY) is False
    only_fan = {"Fan": LIBRARY["Fan"]}
    assert ensure_signature_library(store, only_fan) is True
    assert {t.subject.value for t in store.graph_triples(SIGNATURE_GRAPH) if t.predicate == RDF.type} >= {SIG + "Fan"}
    assert load_signature_library_into(store, only_fan) == len(signature_triples(LIBRARY["Fan"]))
    assert store.backend.triple_count(SIGNATURE_GRAPH) == len(signature_triples(LIBRARY["Fan"]))


def _models_for(store: GraphStore, class_iri: str) -> dict[tuple[str, str], str]:
    rows = store.run_named_query("models-for-class", **{"class": class_iri})
    return {(r["id"].value, r["node_id"].value): r["relation"].value for r in rows}


@pytest.fixture(scope="module")
def library_store() -> GraphStore:
    store = GraphStore.embedded(None)
    store.ensure_ontologies()
    ensure_signature_library(store, LIBRARY)
    return store


def test_models_for_a_coil_are_coil_models_and_models_of_coil_subclasses(library_store):
    found = _models_for(library_store, S4BLDG.Coil.value)
    assert found[("WaterCoil", "coil")] == "same"
    assert found[("HotWaterLoop", "coil_air")] == "same" and found[("HotWaterLoop", "coil_water")] == "same"
    assert found[("HeatingCoil", "coil")] == "subclass"  # models gt:HeatingCoil ⊑ s4bldg:Coil
    assert found[("CoilThermalMass", "coil")] == "same"  # effects too
    assert not any(sig in ("Fan", "TemperatureSensor", "PIController") for sig, _ in found)
    broader = _models_for(library_store, S4BLDG.EnergyConversionDevice.value)
    assert set(broader.values()) == {"subclass"} and ("WaterCoil", "coil") in broader


def test_a_model_of_a_superclass_applies_to_the_subclass(library_store):
    generic = signature_from_dict({
        "id": "GenericConverter", "model": "service.components.water_coil:WaterCoil", "modeled_nodes": ["device"],
        "nodes": {"device": {"classes": ["s4bldg:EnergyConversionDevice"]}},
    })
    store = GraphStore.embedded(None)
    store.ensure_ontologies()
    ensure_signature_library(store, {"GenericConverter": generic, "WaterCoil": LIBRARY["WaterCoil"]})
    assert _models_for(store, S4BLDG.Coil.value) == {("GenericConverter", "device"): "superclass", ("WaterCoil", "coil"): "same"}
    assert _models_for(store, S4BLDG.Fan.value) == {}


def test_assembled_components_lists_nodes_signatures_and_roles(case_store):
    model = assemble(case_store, "case", library=LIBRARY)
    case_store.write_graph(case_store.assembly_graph("case"), assembly_triples(model, "case"))
    rows = case_store.run_named_query("assembled-components", model="case")
    assert len(rows) == sum(len(c.modeled_nodes) for c in model.components.values())
    by_node = {r["node"].value: r for r in rows}
    fan = by_node[EX + "supply_fan"]
    assert fan["signature"].value == SIG + "Fan" and fan["role"].value == "component"
    assert "signature_label" not in fan  # the library graph is not loaded in this store
    assert by_node[EX + "fan_power_meter"]["role"].value == "calibration target"
    assert by_node[EX + "supply_air_flow_meter"]["role"].value == "boundary input"
    assert by_node[EX + "check_valve"]["component"] == by_node[EX + "heating_valve"]["component"]  # one HotWaterLoop
    ensure_signature_library(case_store, LIBRARY)
    rows = case_store.run_named_query("assembled-components", model="case")
    assert {r["signature_label"].value for r in rows if r["node"].value == EX + "supply_fan"} == {LIBRARY["Fan"].label}
    assert case_store.run_named_query("assembled-components", model="other") == []
