"""A command-driven water coil reads the water sensors the graph gives it: a supply water temperature
sensor upstream of its valve feeds the coil (its parameter is then not estimated), a position sensor
on the valve reads the stem, and neither is taken for the coil's air inlet."""

import pytest

from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.model.effect_splicing import EffectRequest
from service.resources import examples_dir

EX = "https://example.org/flexlab-x3a#"

WATER_SENSORS = {
    "saref": """
ex:hot_water_supply_sensor a s4bldg:Sensor ;
    saref:observes ex:hot_water_supply_temperature ;
    saref:isMeasuredIn unit:DEG_C ;
    gt:timeSeriesId "hot water supply" ;
    fso:suppliesFluidTo ex:heating_coil_valve .
ex:hot_water_supply_temperature a saref:Temperature .
ex:heating_valve_position_sensor a s4bldg:Sensor ;
    saref:observes ex:heating_coil_valve_position ;
    saref:isMeasuredIn unit:UNITLESS ;
    gt:timeSeriesId "heating valve position" .
""",
    "brick": """
ex:hot_water_supply_sensor a brick:Entering_Hot_Water_Temperature_Sensor ;
    brick:isPointOf ex:heating_coil ;
    brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "hot water supply" ] .
ex:hot_water_return_sensor a brick:Leaving_Hot_Water_Temperature_Sensor ;
    brick:isPointOf ex:heating_coil ;
    brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "hot water return" ] .
ex:heating_valve_position_sensor a brick:Valve_Position_Sensor ;
    brick:isPointOf ex:heating_coil_valve ;
    brick:hasUnit unit:PERCENT ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "heating valve position" ] .
""",
}


@pytest.fixture(scope="module")
def store():
    store = GraphStore.embedded(None)
    for name, folder in (("saref", "flexlab_ahu"), ("brick", "flexlab_ahu_brick")):
        text = (examples_dir() / folder / "model.ttl").read_text(encoding="utf-8")
        store.load_model(name, (text + WATER_SENSORS[name]).encode())
    return store


def _wires(model):
    name = {iri: c.node.removeprefix(EX) for iri, c in model.components.items()}
    return {(name[c.source], c.source_port, name[c.target], c.target_port) for c in model.connections}


@pytest.mark.parametrize("name", ["saref", "brick"])
def test_a_supply_water_sensor_feeds_the_coil_and_its_position_sensor_is_a_target(store, name):
    """In Brick, the coil's entering hot water point is placed upstream of its valve; its leaving water
    point is a column nothing reads."""
    model = assemble(store, name)
    wires = _wires(model)
    assert ("hot_water_supply_sensor", "measured_value", "heating_coil", "supply_water_temperature") in wires
    # the water sensor reaches the coil through its valve: it is not the coil's air inlet
    assert ("cooling_coil", "outlet_air_temperature", "heating_coil", "inlet_air_temperature") in wires
    assert ("heating_coil", "valve_position", "heating_valve_position_sensor", "measured_value") in wires
    assert model.component_for_node(EX + "heating_valve_position_sensor").iri in model.targets
    assert model.component_for_node(EX + "hot_water_supply_sensor").iri in model.boundary_inputs
    estimated = {(ref.component, ref.name) for ref in model.estimated_parameters}
    heating, cooling = (model.component_for_node(EX + n).iri for n in ("heating_coil", "cooling_coil"))
    assert (heating, "supply_water_temperature") not in estimated  # measured instead
    assert (cooling, "supply_water_temperature") in estimated  # no sensor on the chilled water
    assert (heating, "water_side_conductance") in estimated
    if name == "brick":
        assert "hot_water_return_sensor: measured, but no component reads it (what it drives or sets is not in the " \
            "model): left out, its column is not needed" in model.notes


@pytest.mark.parametrize(("effect", "position_reads_command"), [("ValveLeakage", True), ("ValveStuck", False)])
def test_a_leak_leaves_the_position_reading_at_the_command_a_stuck_stem_does_not(store, effect, position_reads_command):
    model = assemble(store, "saref", extra_effects=[EffectRequest(effect, EX + "heating_coil_valve")])
    sensor = model.component_for_node(EX + "heating_valve_position_sensor").iri
    feeds = {(model.components[c.source].signature.id, c.source_port)
             for c in model.connections if c.target == sensor}
    assert feeds == ({("CommandSignal", "measured_value")} if position_reads_command
                     else {("HeatingCoil", "valve_position")})


@pytest.mark.parametrize("predicate", ["fso:suppliesFluidTo", "fso:returnsFluidTo"])
def test_a_sensor_on_a_second_outlet_of_a_one_node_coil_is_flagged_or_left_out(predicate):
    """A return water sensor after a coil that is one node (air and water) reads, to the pattern, the
    coil's outlet air: the assembly says so and how to state it; stated as returned water, it is left out."""
    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text(encoding="utf-8") + f"""
ex:hot_water_return_sensor a s4bldg:Sensor ;
    saref:observes ex:hot_water_return_temperature ;
    saref:isMeasuredIn unit:DEG_C ;
    gt:timeSeriesId "hot water return" .
ex:hot_water_return_temperature a saref:Temperature .
ex:heating_coil {predicate} ex:hot_water_return_sensor .
"""
    store = GraphStore.embedded(None)
    store.load_model("return", text.encode())
    model = assemble(store, "return")
    flagged = [n for n in model.notes if n.startswith("hot_water_return_sensor: read as the outlet air of heating_coil")]
    if predicate == "fso:suppliesFluidTo":
        assert len(flagged) == 1 and "feeds 2 nodes (hot_water_return_sensor, supply_fan)" in flagged[0]
        assert model.component_for_node(EX + "hot_water_return_sensor").iri in model.targets
    else:
        assert not flagged and model.component_for_node(EX + "hot_water_return_sensor") is None
    assert not any("supply_air_temperature_sensor: read as" in n for n in model.notes)


def test_a_coil_of_unstated_service_is_a_water_coil_and_the_assembly_says_how_to_narrow_it():
    """A coil typed only s4bldg:Coil gets the WaterCoil, whose supply water prior spans chilled to hot
    water; the assembly says so and names the types that narrow it (a walkthrough's plain coil got the
    wide prior in silence). The typed coil beside it gets no such note."""
    text = (examples_dir() / "flexlab_ahu" / "model.ttl").read_text()
    assert text.count("ex:cooling_coil a gt:CoolingCoil") == 1
    store = GraphStore.embedded(None)
    store.load_model("plain", text.replace("ex:cooling_coil a gt:CoolingCoil", "ex:cooling_coil a s4bldg:Coil").encode(),
                     "turtle")
    model = assemble(store, "plain")
    coils = {c.signature.id for c in model.components.values() if EX + "cooling_coil" in c.modeled_nodes}
    assert coils == {"WaterCoil"}
    said = [n for n in model.notes if "unstated service" in n]
    assert said == ["cooling_coil: modelled as a water coil of unstated service (its supply water, where no sensor reads "
                    "it, anywhere from 2 to 90 °C): type it gt:CoolingCoil or gt:HeatingCoil to narrow it"]
