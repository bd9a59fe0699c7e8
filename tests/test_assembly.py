"""Assembly of the case study: components, wiring, boundary inputs, targets, parameters, effects."""

import pytest
from case_study import CASE_STUDY, EX

from service.assembly import AssemblyError, EffectRequest, IncompleteModelError, assemble
from service.assembly_triples import assembly_triples
from service.effect_recording import applied_effect_triples
from service.resources import signatures_dir
from service.signature import load_signature_library
from service.store import GraphStore


def _nodes(model, components):
    return sorted(model.components[c].node.rsplit("#", 1)[-1] for c in components)


def test_case_study_assembles_like_the_paper(case_store):
    model = assemble(case_store, "case")
    assert _nodes(model, model.boundary_inputs) == [
        "fan_inlet_air_temperature_sensor", "setpoint_schedule",
        "supply_air_flow_meter", "supply_water_temperature_sensor"]
    assert _nodes(model, model.targets) == [
        "coil_inlet_water_temperature_sensor", "coil_outlet_air_temperature_sensor",
        "coil_outlet_water_temperature_sensor", "fan_power_meter", "valve_position_sensor"]
    mapped = {ref.name: ref.value for ref in model.mapped_parameters}
    assert mapped == {"nominal_air_flow": 1.5, "nominal_power": pytest.approx(1800.0), "valve_flow_coefficient": 2.5}
    assert len(model.estimated_parameters) == 14
    loop = model.component_for_node(EX + "heating_valve")
    assert loop.signature.id == "HotWaterLoop" and EX + "check_valve" in loop.modeled_nodes
    wires = {(model.components[c.source].signature.id, c.source_port, model.components[c.target].node.rsplit("#")[-1], c.target_port)
             for c in model.connections}
    assert ("PIController", "control_signal", "heating_coil_air_side", "valve_position") in wires
    assert ("TemperatureSensor", "measured_value", "coil_outlet_air_temperature_controller", "measured_value") in wires
    assert ("Fan", "outlet_air_mass_flow", "heating_coil_air_side", "air_mass_flow") in wires


def test_assembly_triples_describe_every_component(case_store):
    model = assemble(case_store, "case")
    triples = assembly_triples(model, "case")
    case_store.write_graph(case_store.assembly_graph("case"), triples)
    rows = case_store.query(
        "PREFIX gt: <https://w3id.org/graphtwin/ontology#> SELECT ?c ?node WHERE { GRAPH ?g { ?a gt:hasTarget ?c . ?c gt:represents ?node } }")
    assert len(rows) == 5


def test_a_recorded_effect_is_spliced_on_reassembly(tmp_path):
    library = load_signature_library(signatures_dir())
    extra = "\n".join(f"{t.subject} {t.predicate} {t.object} ." for t in applied_effect_triples(library["FanMotorHeat"], EX + "supply_fan"))
    store = GraphStore.embedded(None)
    store.load_model("with_heat", CASE_STUDY.read_bytes() + b"\n" + extra.encode())
    model = assemble(store, "with_heat")
    effect = [c for c in model.components.values() if c.signature.id == "FanMotorHeat"]
    assert len(effect) == 1
    coil = model.component_for_node(EX + "heating_coil_air_side").iri
    into_coil = [c for c in model.connections if (c.target, c.target_port) == (coil, "inlet_air_temperature")]
    assert [model.components[c.source].signature.id for c in into_coil] == ["FanMotorHeat"]
    assert {r.name for r in model.estimated_parameters} >= {"motor_heat_fraction"}


def test_an_effect_where_its_pattern_does_not_match_is_refused(case_store):
    with pytest.raises(AssemblyError, match="does not apply"):
        assemble(case_store, "case", extra_effects=[EffectRequest("FanMotorHeat", EX + "heating_valve")])


def test_a_missing_upstream_source_is_reported_in_words():
    store = GraphStore.embedded(None)
    text = CASE_STUDY.read_text().replace("fso:suppliesFluidTo ex:supply_fan .", ".")
    store.load_model("broken", text.encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "broken")
    assert any("supply_fan" in p and "upstream" in p for p in info.value.problems)
