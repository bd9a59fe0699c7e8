"""Assembly of the case study: components, wiring, boundary inputs, targets, parameters, effects."""

import dataclasses

import pandas as pd
import pytest
from case_study import CASE_STUDY, EX, case_study_data, case_study_with_effect

from service.components.library import SignatureLibrary
from service.data.model_series import read_model_data
from service.errors import AssemblyError, IncompleteModelError
from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.model.assembly_triples import assembly_triples
from service.model.effect_splicing import EffectRequest
from service.model.wiring import measured_outputs, parameter_label


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
    # the fan's power is metered: its impeller's heat is counted (fixed, not estimated)
    assert mapped == {"nominal_air_flow": 1.5, "nominal_power": pytest.approx(1800.0), "valve_flow_coefficient": 2.5,
                      "impeller_heat_share": 0.3}
    assert len(model.estimated_parameters) == 17
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
    library = SignatureLibrary.load()
    store = GraphStore.embedded(None)
    store.load_model("with_heat", case_study_with_effect(library["FanMotorHeat"], EX + "supply_fan"))
    model = assemble(store, "with_heat")
    effect = [c for c in model.components.values() if c.signature.id == "FanMotorHeat"]
    assert len(effect) == 1
    coil = model.component_for_node(EX + "heating_coil_air_side").iri
    into_coil = [c for c in model.connections if (c.target, c.target_port) == (coil, "inlet_air_temperature")]
    assert [model.components[c.source].signature.id for c in into_coil] == ["FanMotorHeat"]
    assert {r.name for r in model.estimated_parameters} >= {"motor_heat_fraction"}
    # a key read as people read it: the node and the name, for the effect's parameter and a component's
    labels = {parameter_label(r.key) for r in model.estimated_parameters}
    assert {"supply_fan.motor_heat_fraction", "supply_fan.c1"} <= labels and not any("/" in label for label in labels)


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


def test_two_units_whose_nodes_share_local_names_keep_every_component():
    """Two copies of the case study in two namespaces: ``…/unit1#supply_fan`` and
    ``…/unit2#supply_fan`` are two fans, two components (before, one replaced the other)."""
    text = CASE_STUDY.read_text()
    units = [text.replace(EX, EX.replace("case-study#", f"case-study/unit{k}#")) for k in (1, 2)]
    store = GraphStore.embedded(None)
    store.ensure_ontologies()
    store.load_model("two", "\n".join(units).encode())
    store.load_model("case", CASE_STUDY)
    one = assemble(store, "case")
    both = assemble(store, "two")
    assert len(both.components) == 2 * len(one.components)
    assert len(both.targets) == 10 and len(both.boundary_inputs) == 2 * len(one.boundary_inputs)
    fans = sorted(c.node for c in both.components.values() if c.signature.id == "Fan")
    assert [f.rsplit("/", 1)[-1] for f in fans] == ["unit1#supply_fan", "unit2#supply_fan"]
    # each unit's coil is fed by its own fan
    for unit in ("unit1", "unit2"):
        coil = both.component_for_node(EX.replace("case-study#", f"case-study/{unit}#") + "heating_coil_air_side").iri
        fed_by = {both.components[c.source].node for c in both.connections if c.target == coil and c.target_port == "air_mass_flow"}
        assert fed_by == {EX.replace("case-study#", f"case-study/{unit}#") + "supply_fan"}


def test_a_device_whose_upstream_model_lacks_its_quantity_and_that_nothing_reads_is_left_out_with_a_note(tmp_path):
    """The coil outlet water sensor moved after the check valve: the hot-water loop models the check
    valve but gives no temperature there, so the sensor cannot be a target — said, not silent. No
    component reads it either, so it is left out: a data file without its column is read (a user's
    coil inlet water sensor between the valve and the coil had made every calibration refuse the file)."""
    text = CASE_STUDY.read_text()
    for old, new in (("fso:suppliesFluidTo ex:coil_outlet_water_temperature_sensor .", "fso:suppliesFluidTo ex:check_valve ."),
                     ('gt:timeSeriesId "coil_outlet_water_temperature" ;\n    fso:suppliesFluidTo ex:check_valve .',
                      'gt:timeSeriesId "coil_outlet_water_temperature" .'),
                     ("fso:suppliesFluidTo ex:return_water_pipe .\n\nex:return_water_pipe",
                      "fso:suppliesFluidTo ex:coil_outlet_water_temperature_sensor .\n\nex:return_water_pipe")):
        assert old in text
        text = text.replace(old, new)
    store = GraphStore.embedded(None)
    store.load_model("moved", text.encode())
    model = assemble(store, "moved")
    assert model.component_for_node(EX + "coil_outlet_water_temperature_sensor") is None  # nothing reads it either
    assert [note for note in model.notes if "coil_outlet_water_temperature_sensor" in note] == [
        next(note for note in model.notes
             if f"{EX}check_valve is modelled by HotWaterLoop, which has no output carrying 'temperature' there" in note
             and note.endswith("coil_outlet_water_temperature_sensor cannot be a calibration target and no component "
                               "reads it: left out, its column is not needed"))]
    data = tmp_path / "without_its_column.csv"
    case_study_data(data, seed=0, n_days=0.5)
    frame = pd.read_csv(data).drop(columns=["coil_outlet_water_temperature"])
    frame.to_csv(data, index=False)
    assert read_model_data(model, data).series  # the data file need not have the column


def test_two_nearest_partners_alike_are_a_note_naming_both():
    """A second fan feeding the coil in parallel: the coil's nearest upstream fan is either; one is
    kept (the first in IRI order, deterministic) and the note names the one set aside."""
    store = GraphStore.embedded(None)
    store.load_model("parallel", CASE_STUDY.read_text().encode()
                     + b"\nex:supply_fan_2 a s4bldg:Fan ; fso:suppliesFluidTo ex:heating_coil_air_side .\n")
    model = assemble(store, "parallel", allow_incomplete=True)  # the second fan has no flow meter
    [note] = [n for n in model.notes if "ways alike" in n]
    assert note.startswith("heating_coil_air_side: HotWaterLoop matches 4 ways alike; kept air_inlet = supply_fan, fan = supply_fan")
    assert "fan = supply_fan_2" in note
    assert model.component_for_node(EX + "heating_coil_air_side").bindings["fan"] == EX + "supply_fan"


SHARED_PUMP = """@prefix ex: <https://example.org/plant/> . @prefix saref: <https://saref.etsi.org/core/> .
@prefix s4bldg: <https://saref.etsi.org/saref4bldg/> . @prefix fso: <https://w3id.org/fso#> .
@prefix gt: <https://w3id.org/graphtwin/ontology#> . @prefix unit: <http://qudt.org/vocab/unit/> .
ex:sws a s4bldg:Sensor ; saref:observes ex:sws_t ; saref:isMeasuredIn unit:DEG_C ; fso:suppliesFluidTo ex:pump .
ex:sws_t a saref:Temperature . ex:pump a s4bldg:Pump ; fso:suppliesFluidTo ex:v1, ex:v2 .
""" + "".join(f"""
ex:v{k} a s4bldg:Valve ; saref:hasProperty ex:v{k}_pos ; fso:suppliesFluidTo ex:c{k}_w . ex:v{k}_pos a gt:OpeningPosition .
ex:c{k}_w a s4bldg:Coil ; fso:transfersHeatTo ex:c{k}_a ; fso:suppliesFluidTo ex:cv{k} . ex:cv{k} a s4bldg:Valve .
ex:in{k} a s4bldg:Sensor ; saref:observes ex:in{k}_t ; saref:isMeasuredIn unit:DEG_C ; fso:suppliesFluidTo ex:fm{k} .
ex:in{k}_t a saref:Temperature . ex:fm{k}_q a gt:FlowRate .
ex:fm{k} a s4bldg:FlowMeter ; saref:observes ex:fm{k}_q ; saref:isMeasuredIn unit:M3-PER-SEC ; fso:suppliesFluidTo ex:fan{k} .
ex:fan{k} a s4bldg:Fan ; fso:suppliesFluidTo ex:c{k}_a . ex:c{k}_a a s4bldg:Coil ; fso:suppliesFluidTo ex:out{k} .
ex:out{k} a s4bldg:Sensor ; saref:observes ex:out{k}_t ; saref:isMeasuredIn unit:DEG_C . ex:out{k}_t a saref:Temperature .
ex:ctl{k} a s4bldg:Controller ; saref:observes ex:out{k}_t ; saref:controls ex:v{k}_pos ; saref:hasProfile ex:sp{k} .
ex:sp{k} a gt:SetpointSchedule ; saref:isMeasuredIn unit:DEG_C .""" for k in (1, 2))


def test_a_match_that_loses_a_node_it_needs_is_reported_as_the_reason():
    """One pump serving two coils: the hot-water loop of coil 2 matches but needs the pump, which the
    loop of coil 1 represents; the report says so, not only which triples another signature missed."""
    store = GraphStore.embedded(None)
    store.load_model("plant", SHARED_PUMP.encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "plant")
    assert ("https://example.org/plant/c2_a is not modelled: HotWaterLoop matches there but also needs "
            "https://example.org/plant/pump: the HotWaterLoop at c1_a represents it already") in info.value.problems


def test_a_nominal_value_without_its_unit_is_estimated_with_a_note(case_store):
    text = CASE_STUDY.read_text()
    old = 'saref:hasValue "1.8"^^xsd:double ;\n    saref:isMeasuredIn unit:KiloW .'
    assert old in text
    store = GraphStore.embedded(None)
    store.load_model("no_unit", text.replace(old, 'saref:hasValue "1.8"^^xsd:double .').encode())
    model = assemble(store, "no_unit")
    assert "nominal_power" not in {ref.name for ref in model.mapped_parameters}
    assert (f"supply_fan: parameter nominal_power of Fan is estimated, not mapped: the graph gives 1.8 but no unit "
            f"for it (add <{EX}supply_fan_nominal_power> <https://saref.etsi.org/core/isMeasuredIn> <a QUDT unit IRI> .)"
            ) in model.notes
    assert not [n for n in assemble(case_store, "case").notes if "no unit" in n]  # with its unit: no note


def test_the_fans_impeller_heat_is_counted_where_a_meter_measures_its_power_and_nowhere_else(case_store):
    def impeller_share(model):
        return {ref.name: ref.value for ref in model.mapped_parameters}["impeller_heat_share"]

    assert impeller_share(assemble(case_store, "case")) == 0.3
    text = CASE_STUDY.read_text()
    meter = ('ex:fan_power_meter a saref:Meter ;\n    rdfs:label "Supply fan power meter" ;\n'
             '    saref:observes ex:supply_fan_power ;')
    assert meter in text
    store = GraphStore.embedded(None)
    unmetered_text = text.replace(meter, 'ex:fan_power_meter rdfs:label "Supply fan power meter" ;')
    store.load_model("unmetered", unmetered_text.encode())
    unmetered = assemble(store, "unmetered")
    assert "impeller_heat_share" not in {ref.name for ref in unmetered.estimated_parameters}
    assert impeller_share(unmetered) == 0.0
    # an effect spliced between an output and its sensor leaves the output measured
    offset = EffectRequest("SensorOffset", EX + "coil_outlet_air_temperature_sensor")
    model = assemble(case_store, "case", extra_effects=[offset])
    coil = model.component_for_node(EX + "heating_coil_air_side").iri
    assert "outlet_air_temperature" in measured_outputs(model.connections, model.components, model.targets)[coil]
    spliced = [c for c in model.connections if model.components[c.target].signature.id == "SensorOffset"]
    cut = [c for c in model.connections if c not in spliced]
    assert "outlet_air_temperature" not in measured_outputs(cut, model.components, model.targets)[coil]
    assert impeller_share(model) == 0.3


def test_an_effect_splicing_a_port_its_host_lacks_is_refused_by_name(case_store):
    """The pattern matches, but the component modelling the node has no such port: an assembly
    error naming the port and the host's ports (before, the simulation failed with a KeyError)."""
    library = SignatureLibrary.load()
    offset = library["SensorOffset"]
    library["SensorOffset"] = dataclasses.replace(offset, splice=dataclasses.replace(offset.splice, port="inlet_value"))
    with pytest.raises(AssemblyError, match=r"splices input 'inlet_value', which service\.components\.measuring_device:MeasuringDevice "
                                            r"\(modelling .*coil_outlet_air_temperature_sensor\) does not have; its inputs: measured_value"):
        assemble(case_store, "case", library=library,
                 extra_effects=[EffectRequest("SensorOffset", EX + "coil_outlet_air_temperature_sensor")])


FLEXLAB = "https://example.org/flexlab-x3a#"


def _fed_by(model, node: str, port: str) -> set[str]:
    component = model.component_for_node(FLEXLAB + node).iri
    return {model.components[c.source].node.removeprefix(FLEXLAB)
            for c in model.connections if c.target == component and c.target_port == port}


def test_coils_take_their_air_flow_from_the_fan_downstream_or_else_upstream():
    """The FLEXLAB unit draws its air through the coils; moved to blow through them (mixed air →
    fan → cooling coil → heating coil → supply air), its coils read the fan upstream."""
    from service.resources import examples_dir

    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text(encoding="utf-8")
    blow_through = (text.replace('"AHU: Mixed Air Temperature" ;\n    fso:suppliesFluidTo ex:cooling_coil .',
                                 '"AHU: Mixed Air Temperature" ;\n    fso:suppliesFluidTo ex:supply_fan .')
                    .replace("fso:suppliesFluidTo ex:supply_fan .\nex:heating_coil_valve",
                             "fso:suppliesFluidTo ex:supply_air_temperature_sensor .\nex:heating_coil_valve")
                    .replace("saref:hasProperty ex:supply_fan_speed ;\n    fso:suppliesFluidTo ex:supply_air_temperature_sensor .",
                             "saref:hasProperty ex:supply_fan_speed ;\n    fso:suppliesFluidTo ex:cooling_coil ."))
    assert blow_through.count("fso:suppliesFluidTo ex:supply_fan .") == 1  # every replacement took
    store = GraphStore.embedded(None)
    store.ensure_ontologies()
    store.load_model("draw", text.encode())
    store.load_model("blow", blow_through.encode())
    draw, blow = assemble(store, "draw"), assemble(store, "blow")
    for model in (draw, blow):
        assert _fed_by(model, "heating_coil", "air_mass_flow") == {"supply_fan"}
        assert _fed_by(model, "cooling_coil", "air_mass_flow") == {"supply_fan"}
    assert _fed_by(blow, "cooling_coil", "inlet_air_temperature") == {"supply_fan"}
    assert _fed_by(draw, "cooling_coil", "inlet_air_temperature") == {"mixed_air_temperature_sensor"}
    # the effects that need the air flow apply to a draw-through coil too
    with_gain = assemble(store, "draw", extra_effects=[EffectRequest("ConstantHeatGain", FLEXLAB + "heating_coil")])
    assert len(with_gain.components) == len(draw.components) + 1


def test_a_coil_without_a_fan_either_way_is_reported_with_both_directions_and_the_stops():
    from service.resources import examples_dir

    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text(encoding="utf-8")
    fanless = text.replace("fso:suppliesFluidTo ex:supply_fan .\nex:heating_coil_valve", ".\nex:heating_coil_valve")
    store = GraphStore.embedded(None)
    store.load_model("fanless", fanless.encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "fanless")
    assert any(p.startswith(f"{FLEXLAB}heating_coil is not modelled by HeatingCoil: no Fan upstream or downstream of "
                            f"{FLEXLAB}heating_coil along https://w3id.org/fso#suppliesFluidTo (the search stops at "
                            "MixingBox instances, building spaces") for p in info.value.problems), info.value.problems


def test_a_loop_without_its_check_valve_is_reported_where_the_connection_is_missing():
    """The hot-water loop's pattern reaches from the coil's air side to its water side and on to a
    valve downstream: a loop drawn without that valve is reported as that valve missing downstream
    of the water side (it had said the water side lacks a coil to heat, the first triple touching
    the air side having matched), and the water side, held by the partial match, gets no line of
    its own for that signature."""
    text = CASE_STUDY.read_text(encoding="utf-8").replace(
        "    fso:suppliesFluidTo ex:check_valve .", "    fso:suppliesFluidTo ex:return_water_pipe .")
    store = GraphStore.embedded(None)
    store.load_model("no-check-valve", text.encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "no-check-valve")
    loop = [p for p in info.value.problems if "by HotWaterLoop" in p]
    assert loop == [f"{EX}heating_coil_air_side is not modelled by HotWaterLoop: no Valve downstream of "
                    f"{EX}heating_coil_water_side along https://w3id.org/fso#suppliesFluidTo (the search stops at "
                    "building spaces, boilers, chillers and cooling towers; signature "
                    "hot_water_loop.toml)"], info.value.problems  # its name, not the server's path


@pytest.mark.parametrize("typo", ["fan", "Fam", "Fna", "Fann"])
def test_a_misspelt_class_that_leaves_a_pattern_unmatched_is_named_in_the_error_with_its_spelling(typo):
    """``s4bldg:fan``: the coil then has no fan, and the error says why first (the class declared
    nowhere, and the declared class it differs from only in case); a short name one letter off
    (replaced, swapped, added), which a similarity ratio on three letters does not reach, too."""
    text = CASE_STUDY.read_text(encoding="utf-8")
    assert "ex:supply_fan a s4bldg:Fan" in text
    store = GraphStore.embedded(None)
    store.load_model("typo", text.replace("ex:supply_fan a s4bldg:Fan", f"ex:supply_fan a s4bldg:{typo}").encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "typo")
    assert info.value.problems[0].startswith(f"supply_fan: its class https://saref.etsi.org/saref4bldg/{typo}"), info.value.problems
    assert info.value.problems[0].endswith("(did you mean https://saref.etsi.org/saref4bldg/Fan?)")


def test_misspelt_official_terms_are_notes_naming_the_node_and_the_term_meant():
    """``s4bldg:Sensr``: the sensor is still modelled (it observes a property), the model is the same,
    and a note names the node, the class and the one it resembles. ``fso:suppliesFluidToo``: the coil
    no longer feeds the sensor, which becomes a boundary input, and a note says which property no
    signature follows. ``s4bldg:nominalAirflowRate``: the fan's nominal flow is no longer mapped, and
    a note says so. A class or property of the author's own namespace is no note."""
    text = CASE_STUDY.read_text(encoding="utf-8")
    sensor = "ex:coil_outlet_air_temperature_sensor a s4bldg:Sensor"
    feeds = "fso:suppliesFluidTo ex:coil_outlet_air_temperature_sensor"
    assert sensor in text and text.count(feeds) == 1
    store = GraphStore.embedded(None)
    store.load_model("class", text.replace(sensor, sensor.replace("Sensor", "Sensr")).encode())
    store.load_model("property", text.replace(feeds, feeds.replace("FluidTo", "FluidToo")).encode())
    store.load_model("value", text.replace("s4bldg:nominalAirFlowRate", "s4bldg:nominalAirflowRate").encode())
    store.load_model("own", text.replace(sensor, sensor + ", ex:SupplyAirProbe ;\n    ex:installedBy ex:us").encode())
    store.load_model("right", text.encode())
    models = {name: assemble(store, name) for name in ("class", "property", "value", "own", "right")}
    right = models["right"]

    def roles(model):
        return sorted(target.split("/component/")[1] for target in model.targets)

    def new_notes(model):
        return [n for n in model.notes if n not in right.notes]

    node = "https://example.org/ventilation-case-study#coil_outlet_air_temperature_sensor"
    assert new_notes(models["class"]) == [
        f"coil_outlet_air_temperature_sensor: its class https://saref.etsi.org/saref4bldg/Sensr ({node}) is declared "
        "by no loaded ontology (did you mean https://saref.etsi.org/saref4bldg/Sensor?); the node is modelled "
        "from its other types and properties"]
    assert roles(models["class"]) == roles(right) and len(roles(right)) == 5
    assert new_notes(models["property"])[0] == (
        "heating_coil_air_side: its property https://w3id.org/fso#suppliesFluidToo (1 triple, e.g. from "
        "https://example.org/ventilation-case-study#heating_coil_air_side) is declared by no loaded ontology "
        "(did you mean https://w3id.org/fso#suppliesFluidTo?): no signature follows it"), new_notes(models["property"])
    assert len(roles(models["property"])) == 4
    assert new_notes(models["value"])[0] == (
        "supply_fan_nominal_air_flow: the value https://saref.etsi.org/saref4bldg/nominalAirflowRate (1 triple, "
        "e.g. from https://example.org/ventilation-case-study#supply_fan_nominal_air_flow) is declared by no loaded "
        "ontology (did you mean https://saref.etsi.org/saref4bldg/nominalAirFlowRate?): no signature matches it")
    assert len(models["value"].mapped_parameters) == len(right.mapped_parameters) - 1
    assert models["own"].notes == right.notes


def test_a_misspelt_class_on_a_modelled_node_and_on_one_nothing_else_types_names_the_latter_as_the_problem():
    """``s4bldg:Sensr`` on the coil's sensor (modelled from its properties) and on a spare sensor
    nothing else types: the spare one is left out, so the model is incomplete and the problem names
    it; a misspelt property elsewhere is among the error's notes, not its problems."""
    text = CASE_STUDY.read_text(encoding="utf-8")
    sensor = "ex:coil_outlet_air_temperature_sensor a s4bldg:Sensor"
    feeds = "fso:suppliesFluidTo ex:coil_outlet_air_temperature_sensor"
    store = GraphStore.embedded(None)
    store.load_model("mixed", (text.replace(sensor, sensor.replace("Sensor", "Sensr"))
                               .replace(feeds, feeds.replace("FluidTo", "FluidToo")) + "\nex:spare_sensor a s4bldg:Sensr .\n").encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "mixed")
    assert info.value.problems == (
        "spare_sensor: its class https://saref.etsi.org/saref4bldg/Sensr (https://example.org/ventilation-case-study#"
        "spare_sensor) is declared by no loaded ontology, and the node has no other type a signature matches: no "
        "component models it (did you mean https://saref.etsi.org/saref4bldg/Sensor?)",)
    assert "fso#suppliesFluidToo" in info.value.notes[0]  # a misspelling first among the notes …
    assert str(info.value).startswith(  # … and said at the top, where the problems it may cause begin
        "the model is incomplete (a misspelt term may be why: ")
    assert "the assembly also notes:" in str(info.value)


def test_a_sensor_unit_graphtwin_cannot_read_is_a_note_at_assembly():
    """``unit:DEGC`` for ``unit:DEG_C``: said when the model is assembled, naming the sensor and the
    unit it resembles (it had first surfaced at calibration, blamed on the CSV column); so are a
    temperature sensor in percent and a sensor with no unit (before: said only when data were read)."""
    text = CASE_STUDY.read_text(encoding="utf-8")
    store = GraphStore.embedded(None)
    store.load_model("typo", text.replace(
        "ex:coil_outlet_water_temperature ;\n    saref:isMeasuredIn unit:DEG_C",
        "ex:coil_outlet_water_temperature ;\n    saref:isMeasuredIn unit:DEGC").encode())
    notes = [n for n in assemble(store, "typo").notes if "is not a unit graphtwin knows" in n]
    assert notes == ["coil_outlet_water_temperature_sensor: its unit http://qudt.org/vocab/unit/DEGC "
                     "is not a unit graphtwin knows (did you mean http://qudt.org/vocab/unit/DEG_C?): its column cannot "
                     "be read"], notes
    store.load_model("units", text.replace(
        "ex:coil_outlet_water_temperature ;\n    saref:isMeasuredIn unit:DEG_C", "ex:coil_outlet_water_temperature ;"
    ).replace("ex:coil_outlet_air_temperature ;\n    saref:isMeasuredIn unit:DEG_C",
              "ex:coil_outlet_air_temperature ;\n    saref:isMeasuredIn unit:PERCENT").encode())
    store.load_model("right", text.encode())
    right = assemble(store, "right").notes
    assert [n for n in assemble(store, "units").notes if n not in right] == [
        "coil_outlet_air_temperature_sensor: its unit http://qudt.org/vocab/unit/PERCENT is a unit of fraction, but "
        "the device measures a temperature: its column cannot be read",
        "coil_outlet_water_temperature_sensor: declares no unit (saref:isMeasuredIn, in Brick brick:hasUnit): its "
        f"column cannot be read (add <{EX}coil_outlet_water_temperature_sensor> saref:isMeasuredIn <a QUDT unit IRI> .)"]


def test_a_misspelt_class_that_leaves_its_node_out_is_an_incomplete_model_and_with_leave_a_note():
    """A coil typed with a class no ontology declares matches no signature. The name is close to a
    declared class, so the coil was meant to be a component: the model is incomplete, and the error
    says which class the name is close to, first. Allowed incomplete, the coil is missing and that
    is a note, and so is the valve command that drove it, now read by no component. The same
    misspelling of a Brick class (long names: a nearer match counts) is treated alike."""
    from service.resources import examples_dir

    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text(encoding="utf-8")
    store = GraphStore.embedded(None)
    store.load_model("typo", text.replace("ex:heating_coil a gt:HeatingCoil", "ex:heating_coil a gt:HeatingColi").encode())
    dropped = ("heating_coil: its class https://w3id.org/graphtwin/ontology#HeatingColi "
               "(https://example.org/flexlab-x3a#heating_coil) is declared by no loaded ontology, and the node has no "
               "other type a signature matches: no component models it "
               "(did you mean https://w3id.org/graphtwin/ontology#HeatingCoil?)")
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "typo")
    assert info.value.problems[0] == dropped
    model = assemble(store, "typo", allow_incomplete=True)
    assert model.component_for_node(FLEXLAB + "heating_coil") is None
    assert dropped in model.notes
    assert ("heating_coil_valve_command: measured, but no component reads it (what it drives or sets is not in the "
            "model): left out, its column is not needed") in model.notes
    assert model.component_for_node(FLEXLAB + "heating_coil_valve_command") is None  # no column asked of the data
    store.load_model("right", text.encode())
    right = assemble(store, "right")
    assert not any("declared by no loaded ontology" in n or "heating_coil_valve_command" in n for n in right.notes), right.notes

    brick = (examples_dir() / "flexlab_ahu_brick" / "model.ttl").read_text(encoding="utf-8")
    assert brick.count("brick:Hot_Water_Coil") == 1
    store.load_model("brick", brick.replace("brick:Hot_Water_Coil", "brick:Hot_Watter_Coil").encode())
    with pytest.raises(IncompleteModelError) as info:
        assemble(store, "brick")
    assert info.value.problems[0].endswith("(did you mean https://brickschema.org/schema/Brick#Hot_Water_Coil?)")


def test_a_model_nothing_matches_is_an_error_not_an_empty_assembly():
    store = GraphStore.embedded(None)
    store.load_model("bare", b"<https://example.org/a> <https://example.org/b> <https://example.org/c> .", "nt")
    with pytest.raises(AssemblyError, match="no signature of the library matches anything in model bare"):
        assemble(store, "bare")


def test_a_room_in_twin4builds_spelling_stops_a_traverse_like_a_building_space():
    """``s4bldg:Space`` (no SAREF4BLDG version has it; Twin4Build writes it for BuildingSpace): the
    supply air sensor before the room is no inlet of the fan after it (it was wired through the room)."""
    from service.resources import examples_dir

    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text(encoding="utf-8")
    assert "ex:test_cell a s4bldg:BuildingSpace" in text
    store = GraphStore.embedded(None)
    store.load_model("t4b", text.replace("ex:test_cell a s4bldg:BuildingSpace", "ex:test_cell a s4bldg:Space").encode())
    store.load_model("saref", text.encode())
    wiring = {name: {(c.source, c.source_port, c.target, c.target_port) for c in assemble(store, name).connections}
              for name in ("t4b", "saref")}
    assert {(s.rsplit("/", 1)[-1], sp, t.rsplit("/", 1)[-1], tp) for s, sp, t, tp in wiring["t4b"]} == {
        (s.rsplit("/", 1)[-1], sp, t.rsplit("/", 1)[-1], tp) for s, sp, t, tp in wiring["saref"]}


@pytest.mark.parametrize("value", ["-1.5", "NaN"])
def test_a_mapped_value_outside_its_bounds_is_a_note_at_assembly(value):
    """Said where the graph is read, not only when a calibration refuses it."""
    text = CASE_STUDY.read_text().replace('saref:hasValue "1.5"^^xsd:double', f'saref:hasValue "{value}"^^xsd:double')
    store = GraphStore.embedded(None)
    store.load_model("odd", text.encode())
    model = assemble(store, "odd")
    assert any(n.startswith(f"nominal_air_flow of {EX}supply_fan is mapped from the graph to {float(value):g} m3/s, "
                            "outside its bounds") and "a calibration refuses it" in n for n in model.notes), model.notes


def test_a_room_whose_class_the_model_makes_equivalent_to_a_building_space_stops_a_traverse():
    """``ex:Office owl:equivalentClass s4bldg:BuildingSpace`` in the model: an office is a building
    space (it was wired through, and its class called undeclared)."""
    from service.resources import examples_dir

    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text(encoding="utf-8")
    office = text.replace("ex:test_cell a s4bldg:BuildingSpace", "ex:test_cell a ex:Office") + (
        "\nex:Office <http://www.w3.org/2002/07/owl#equivalentClass> s4bldg:BuildingSpace .\n")
    store = GraphStore.embedded(None)
    store.load_model("office", office.encode())
    store.load_model("saref", text.encode())
    models = {name: assemble(store, name) for name in ("office", "saref")}
    wiring = {name: {(c.source.rsplit("/", 1)[-1], c.source_port, c.target.rsplit("/", 1)[-1], c.target_port)
                     for c in model.connections} for name, model in models.items()}
    assert wiring["office"] == wiring["saref"]
    assert not any("declared by no loaded ontology" in n for n in models["office"].notes), models["office"].notes


@pytest.mark.parametrize(("effect", "position_reads_command"), [("ValveLeakage", True), ("ValveStuck", False)])
def test_a_seat_leak_changes_the_flow_while_the_position_feedback_reads_the_command(case_store, effect,
                                                                                     position_reads_command):
    """A leak passes water through the seat with the stem where it was commanded: the valve position
    sensor reads the controller's command, the coil the leaking opening. A stuck stem's feedback reads
    where it is stuck."""
    model = assemble(case_store, "case", extra_effects=[EffectRequest(effect, EX + "heating_valve")])
    sensor = model.component_for_node(EX + "valve_position_sensor").iri
    feeds = {(model.components[c.source].signature.id, c.source_port)
             for c in model.connections if c.target == sensor}
    assert feeds == ({("PIController", "control_signal")} if position_reads_command else {("HotWaterLoop", "valve_position")})
    loop = model.component_for_node(EX + "heating_valve").iri
    assert {model.components[c.source].signature.id for c in model.connections
            if c.target == loop and c.target_port == "valve_position"} == {effect}


@pytest.mark.parametrize(("effect", "node", "reached"), [
    ("SensorOffset", "coil_outlet_air_temperature_sensor", {"coil_outlet_air_temperature_sensor", "valve_position_sensor",
                                                            "coil_inlet_water_temperature_sensor",
                                                            "coil_outlet_water_temperature_sensor"}),
    ("FanMotorHeat", "supply_fan", {"coil_outlet_air_temperature_sensor", "valve_position_sensor",
                                    "coil_inlet_water_temperature_sensor", "coil_outlet_water_temperature_sensor"}),
    ("WaterSensorLag", "coil_outlet_water_temperature_sensor", {"coil_outlet_water_temperature_sensor"}),
])
def test_the_sensors_an_effect_can_move_are_those_downstream_of_it_through_the_control_loop(case_store, effect, node,
                                                                                            reached):
    """An offset of the controlled sensor moves every sensor the PI loop drives, never the fan's power
    (a function of the measured air flow alone): a diagnosis had credited it with the fan meter's error
    its refit removed by moving the fan's unidentified curve."""
    base = assemble(case_store, "case")
    model = assemble(case_store, "case", extra_effects=[EffectRequest(effect, EX + node)])
    sources = set(model.components) - set(base.components)
    assert sources and {model.measurement(c).node for c in model.targets_reached_from(sources)} == {
        EX + name for name in reached}
