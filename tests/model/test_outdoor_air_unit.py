"""A dedicated outdoor air unit in Brick (no return air, no mixing box): its outdoor air sensor is the
air its first component takes in, and an isolation damper in its path is passed at the air's
temperature."""

import pytest

from service.graph.store import GraphStore
from service.model.assembly import assemble

NS = "https://example.org/doas#"
UNIT = f"""
@prefix ex:    <{NS}> .
@prefix brick: <https://brickschema.org/schema/Brick#> .
@prefix ref:   <https://brickschema.org/schema/Brick/ref#> .
@prefix unit:  <http://qudt.org/vocab/unit/> .

ex:ahu a brick:Air_Handling_Unit ;
    brick:hasPart ex:heating_coil, ex:heating_valve, ex:supply_fan ;
    brick:hasPoint ex:oat, ex:sat ;
    brick:feeds ex:zone .
ex:zone a brick:HVAC_Zone .
ex:heating_coil a brick:Hot_Water_Coil ; brick:feeds ex:supply_fan .
ex:heating_valve a brick:Hot_Water_Valve ; brick:feeds ex:heating_coil ; brick:hasPoint ex:hv_cmd .
ex:supply_fan a brick:Supply_Fan ; brick:hasPoint ex:sf_cmd .
ex:oat a brick:Outside_Air_Temperature_Sensor ; brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "oat" ] .
ex:sat a brick:Supply_Air_Temperature_Sensor ; brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "sat" ] .
ex:hv_cmd a brick:Valve_Position_Command ; brick:hasUnit unit:PERCENT ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "hv" ] .
ex:sf_cmd a brick:Fan_Speed_Command ; brick:hasUnit unit:PERCENT ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "sf" ] .
"""
DAMPER = """
ex:ahu brick:hasPart ex:oa_damper .
ex:oa_damper a brick:Outside_Damper ; brick:feeds ex:heating_coil ; brick:hasPoint ex:oad_cmd .
ex:oad_cmd a brick:Damper_Position_Command ; brick:hasUnit unit:PERCENT ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "oad" ] .
"""


ON_THE_COIL = "\nex:oat brick:isPointOf ex:heating_coil .\n"  # what the assumption says to state


@pytest.mark.parametrize("extra", ["", DAMPER, ON_THE_COIL], ids=["unit point", "isolation damper", "coil point"])
def test_the_outdoor_air_sensor_feeds_the_first_coil_of_a_unit_without_return_air(extra):
    store = GraphStore.embedded(None)
    store.load_model("doas", (UNIT + extra).encode())
    model = assemble(store, "doas")
    name = {iri: c.node.removeprefix(NS) for iri, c in model.components.items()}
    wires = {(name[c.source], c.source_port, name[c.target], c.target_port) for c in model.connections}
    assert ("oat", "measured_value", "heating_coil", "inlet_air_temperature") in wires
    assert ("heating_coil", "outlet_air_temperature", "supply_fan", "inlet_air_temperature") in wires
    assert [name[t] for t in model.targets] == ["sat"]
    assert not any("oa_damper" in n for n in name.values())  # the damper is passed, not modelled
    assumed = store.query("""PREFIX gt: <https://w3id.org/graphtwin/ontology#>
        SELECT ?about WHERE { ?a a gt:AlignmentAssumption ; gt:assumptionAbout ?about }""", model="doas")
    assert (NS + "oat" in {r["about"].value for r in assumed}) == (extra != ON_THE_COIL)  # a point of the unit only


def test_a_fans_rated_power_in_brick_is_its_nominal_power():
    """A walkthrough's unmetered fan kept the default 1,800 W: no Brick rule read a rated power."""
    store = GraphStore.embedded(None)
    store.load_model("rated", (UNIT + """
ex:supply_fan brick:ratedPowerInput [ brick:value 2.2 ; brick:hasUnit unit:KiloW ] .
""").encode())
    model = assemble(store, "rated")
    power = [r for r in model.mapped_parameters if r.name == "nominal_power"]
    assert len(power) == 1 and power[0].value == pytest.approx(2200.0)
    assert not any(r.name == "nominal_power" for r in model.estimated_parameters)
