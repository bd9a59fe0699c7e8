"""Reading signature files: every malformed key, unknown quantity and port or parameter name the
model class does not declare is refused by a SignatureError naming the file, the key and the problem."""

import re
from pathlib import Path

import pytest

from service.components.component import ComponentModel, Port
from service.components.library import SignatureLibrary, check_model_names, load_signature
from service.graph.units import unit_spec
from service.matching.signature import QUANTITIES, QUANTITY_UNITS, SignatureError, signature_from_dict

TOP = 'id = "T"\nmodel = "service.components.fan:Fan"\nmodeled_nodes = ["fan"]\n'
NODES = '[nodes]\nfan = { classes = ["s4bldg:Fan"] }\n'
EFFECT_TOP = ('id = "E"\nkind = "effect"\nmodel = "service.components.effects.first_order_lag:FirstOrderLag"\n'
              'modeled_nodes = ["coil"]\n[nodes]\ncoil = { classes = ["s4bldg:Coil"] }\n')


def _refused(tmp_path: Path, text: str, key: str, problem: str) -> None:
    """Loading ``text`` raises a SignatureError that reads ``<file>: <key>: …<problem>…``."""
    path = tmp_path / "broken.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SignatureError) as caught:
        load_signature(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {key}: "), message
    assert problem in message, message


@pytest.mark.parametrize("text, key, problem", [
    (TOP.replace("modeled_nodes", 'nodes = "fan"\nmodeled_nodes'), "nodes",
     "expected a table of pattern nodes ([nodes]), got a string"),
    (TOP + 'inputs = { p = "fan" }\n' + NODES, "inputs.p", "expected a table with keys 'source' and 'quantity', got a string"),
    (TOP + 'triples = ["fan"]\n' + NODES, "triples[0]", "got a string"),
    (TOP + 'triples = { subject = "fan" }\n' + NODES, "triples", "expected an array of tables ([[triples]]), got a table"),
    (TOP.replace('["fan"]', '"fan"') + NODES, "modeled_nodes", "expected a non-empty array of node ids, got a string"),
    (TOP + 'parameters = ["nominal_power"]\n' + NODES, "parameters", "got an array"),
    (TOP + 'extra = "notes"\n' + NODES, "extra", "expected a table, got a string"),
    (TOP + "label = 3\n" + NODES, "label", "expected a string, got an integer"),
    (TOP + 'note = ["type it"]\n' + NODES, "note", "expected a string, got an array"),
    (TOP + "complexity = true\n" + NODES, "complexity", "must be an integer"),
    (TOP.replace('"service.components.fan:Fan"', "1") + NODES, "model", "1 must read 'module:Class'"),
    (TOP.replace('"service.components.fan:Fan"', '":Fan"') + NODES, "model", "':Fan' must read 'module:Class'"),
    (TOP.replace('model = "service.components.fan:Fan"', "fmu = 1") + NODES, "fmu", "expected a non-empty string, got an integer"),
    (TOP + '[nodes]\nfan = { classes = "s4bldg:Fan" }\n', "nodes.fan.classes", "got a string"),
    (TOP + NODES + '[[triples]]\nsubject = ["fan"]\npredicate = "fso:feeds"\nobject = "fan"\n',
     "triples[0].subject", "expected a node id (a string), got an array"),
    (TOP + NODES + 'x = { any = true }\n[[triples]]\nsubject = "x"\npredicate = "fso:suppliesFluidTo"\n'
     'object = "fan"\nrule = "traverse"\n', "triples[0]", "traverse needs class-restricted nodes at both ends"),
    (TOP + NODES + '[inputs.inlet_air_temperature]\nsource = "fan"\nquanity = "temperature"\n',
     "inputs.inlet_air_temperature", "unknown key(s) ['quanity']"),
    (TOP + NODES + '[outputs.electric_power]\nquantity = ["power"]\n',
     "outputs.electric_power.quantity", "expected a non-empty string, got an array"),
    (TOP + NODES + 'v = { literal = true }\n[parameters.nominal_power]\nnode = "v"\nunit_node = 1\n',
     "parameters.nominal_power.unit_node", "got an integer"),
    (EFFECT_TOP.replace("[nodes]", 'splice = "coil"\n[nodes]'), "splice", "got a string"),
    (EFFECT_TOP + '[splice]\nnode = "coil"\ninput = "value_in"\noutput = "value_out"\n', "splice",
     "one of 'input' or 'output'"),
    (EFFECT_TOP + '[splice]\nnode = "coil"\noutput = 1\n', "splice.output", "expected a non-empty string, got an integer"),
    (EFFECT_TOP + '[splice]\nnode = "coil"\noutput = "outlet_air_temperature"\nhost_models = "service.components.water_coil:WaterCoil"\n',
     "splice.host_models", "got a string"),
    (TOP + NODES + 'a = { classes = ["s4bldg:Valve"] }\nb = { classes = ["s4bldg:Pump"] }\n[[triples]]\n'
     'subject = "a"\npredicate = "fso:suppliesFluidTo"\nobject = "b"\n', "triples",
     "triples[0] not joined to the modelled node 'fan' by required triples"),
], ids=["nodes-string", "input-string", "triples-strings", "triples-table", "modeled-nodes-string",
        "parameters-array", "extra-string", "label-integer", "note-array", "complexity-boolean", "model-integer", "model-no-module",
        "fmu-integer", "classes-string", "subject-array", "traverse-to-any", "input-unknown-key", "quantity-array",
        "unit-node-integer", "splice-string", "splice-both-sides", "splice-port-integer", "host-models-string",
        "pattern-in-pieces"])
def test_a_malformed_key_is_refused_naming_file_and_key(tmp_path, text, key, problem):
    _refused(tmp_path, text, key, problem)


def test_an_unknown_quantity_is_refused_with_the_known_ones(tmp_path):
    _refused(tmp_path, TOP + NODES + '[outputs.outlet_air_temperature]\nquantity = "temprature"\n',
             "outputs.outlet_air_temperature.quantity", "'temprature' is not a quantity; known: heat_rate, mass_flow")


def test_every_quantity_has_an_unscaled_unit_of_its_own_dimension():
    """The simulator's unit of each quantity a port may carry is a unit graphtwin knows, of the
    quantity's dimension and not scaled (°C, the one with an offset, is the simulator's temperature):
    what the CSV reader converts a column into."""
    dimensions = {"temperature": "temperature", "mass_flow": "mass_flow", "volume_flow": "volume_flow",
                  "power": "power", "heat_rate": "power", "position": "fraction"}
    assert QUANTITIES == set(QUANTITY_UNITS) == set(dimensions)
    for quantity, unit in QUANTITY_UNITS.items():
        spec = unit_spec(unit)
        assert (spec.dimension, spec.multiplier) == (dimensions[quantity], 1.0), (quantity, unit)


@pytest.mark.parametrize("table, key, problem", [
    ('[outputs.outlet_air_temp]\nquantity = "temperature"\n', "outputs.outlet_air_temp",
     "service.components.fan:Fan has no output port 'outlet_air_temp'; its output ports: outlet_air_temperature, "
     "outlet_air_mass_flow, electric_power"),
    ('[inputs.air_flow]\nsource = "fan"\nquantity = "volume_flow"\n', "inputs.air_flow",
     "service.components.fan:Fan has no input port 'air_flow'; its input ports: air_volume_flow, inlet_air_temperature"),
    ('v = { literal = true }\n[parameters.nominal_pwr]\nnode = "v"\n', "parameters.nominal_pwr",
     "service.components.fan:Fan has no parameter 'nominal_pwr'; its parameters: nominal_air_flow, nominal_power"),
], ids=["output", "input", "parameter"])
def test_a_port_or_parameter_the_model_does_not_declare_is_refused(tmp_path, table, key, problem):
    _refused(tmp_path, TOP + NODES + table, key, problem)


@pytest.mark.parametrize("model, problem", [
    ("service.nope:Fan", "model 'service.nope:Fan' cannot be imported: No module named 'service.nope'"),
    ("service.components.fan:Fann", "model 'service.components.fan:Fann' cannot be imported"),
    ("service.matching.signature:Signature", "'service.matching.signature:Signature' is not a ComponentModel"),
], ids=["no-module", "no-class", "not-a-component"])
def test_a_model_that_is_no_component_class_is_refused(tmp_path, model, problem):
    _refused(tmp_path, TOP.replace("service.components.fan:Fan", model) + NODES, "model", problem)


def test_a_splice_port_every_host_model_must_declare(tmp_path):
    splice = '[splice]\nnode = "coil"\noutput = "outlet_air_temp"\nhost_models = ["service.components.water_coil:WaterCoil"]\n'
    _refused(tmp_path, EFFECT_TOP + splice, "splice.output",
             "service.components.water_coil:WaterCoil has no output port 'outlet_air_temp'; its output ports: outlet_air_temperature")
    _refused(tmp_path, EFFECT_TOP + splice.replace("service.components.water_coil:WaterCoil", "service.nope:Coil"),
             "splice.host_models[0]", "model 'service.nope:Coil' cannot be imported")


def test_the_library_refuses_a_broken_file_by_name(tmp_path):
    (tmp_path / "effects").mkdir()
    (tmp_path / "fan.toml").write_text(TOP + NODES, encoding="utf-8")
    broken = tmp_path / "effects" / "typo.toml"
    broken.write_text(TOP.replace('"T"', '"U"') + NODES + 'v = { literal = true }\n[parameters.nominal_pwr]\nnode = "v"\n',
                      encoding="utf-8")
    with pytest.raises(SignatureError, match=re.escape(f"{broken}: parameters.nominal_pwr: service.components.fan:Fan has no")):
        SignatureLibrary.load(tmp_path)


def test_check_model_names_takes_the_class_an_fmu_signature_builds(tmp_path):
    class Lag(ComponentModel):
        inputs = (Port("u", "1"),)
        outputs = (Port("y", "1"),)

    signature = signature_from_dict({
        "id": "Lag", "fmu": "lag.fmu", "modeled_nodes": ["n"], "nodes": {"n": {"classes": ["urn:Lag"]}},
        "outputs": {"z": {"quantity": "position"}},
    }, tmp_path / "lag.toml")
    with pytest.raises(SignatureError, match=re.escape(f"{tmp_path / 'lag.toml'}: outputs.z: {tmp_path / 'lag.fmu'} "
                                                       "has no output port 'z'; its output ports: y")):
        check_model_names(signature, Lag)


@pytest.mark.parametrize("rule, line, key, problem", [
    ("exact", "or_reverse = true", "or_reverse", "only a traverse can fall back to the reverse direction"),
    ("traverse", 'or_reverse = "yes"', "or_reverse", "must be true or false"),
    ("exact", 'stop_at = ["gt:MixingBox"]', "stop_at", "only a traverse has places to stop at"),
    ("traverse", 'stop_at = "gt:MixingBox"', "stop_at", "expected an array of class CURIEs, got a string"),
    ("traverse", 'stop_at = ["nope:MixingBox"]', "stop_at[0]", "nope"),
])
def test_or_reverse_and_stop_at_belong_to_traverses(tmp_path, rule, line, key, problem):
    text = (TOP + NODES + 'coil = { classes = ["s4bldg:Coil"] }\n[[triples]]\nsubject = "coil"\n'
            f'predicate = "fso:suppliesFluidTo"\nobject = "fan"\nrule = "{rule}"\n{line}\n')
    _refused(tmp_path, text, f"triples[0].{key}", problem)


@pytest.mark.parametrize("text, key, problem", [
    (TOP + 'yields_to = ["E"]\n' + NODES, "yields_to", "effects only"),
    (EFFECT_TOP.replace("[nodes]", 'yields_to = "WaterSensorLag"\n[nodes]'), "yields_to",
     "expected an array of effect ids, got a string"),
    (EFFECT_TOP.replace("[nodes]", 'yields_to = ["E"]\n[nodes]'), "yields_to[0]", "'E' must be another effect's id"),
    (EFFECT_TOP.replace("[nodes]", 'yields_to = ["Water Sensor Lag"]\n[nodes]'), "yields_to[0]",
     "must be another effect's id"),
], ids=["component", "string", "itself", "not-an-id"])
def test_yields_to_names_other_effects(tmp_path, text, key, problem):
    splice = '[splice]\nnode = "coil"\ninput = "value_in"\n' if 'kind = "effect"' in text else ""
    _refused(tmp_path, text + splice, key, problem)


def test_the_library_refuses_yielding_to_an_effect_it_does_not_have(tmp_path):
    text = (EFFECT_TOP.replace("[nodes]", 'yields_to = ["WaterSensorLagg"]\n[nodes]')
            + '[splice]\nnode = "coil"\ninput = "value_in"\n')
    (tmp_path / "e.toml").write_text(text, encoding="utf-8")
    with pytest.raises(SignatureError, match=re.escape(f"{tmp_path / 'e.toml'}: yields_to[0]: 'WaterSensorLagg' is not "
                                                       "an effect of the library; its effects: E")):
        SignatureLibrary.load(tmp_path)


def test_a_parameter_the_graph_can_state_names_its_property_and_a_curve_coefficient_none():
    """``graphtwin assemble`` says which property would state an estimated parameter: a user who left
    out a fan's nominal power saw its curve and power one flat direction, and no word of the cause."""
    library = SignatureLibrary.load()
    s4bldg = "https://saref.etsi.org/saref4bldg/"
    assert library["Fan"].stating_property("nominal_power") == s4bldg + "nominalPowerRate"
    assert library["Fan"].stating_property("nominal_air_flow") == s4bldg + "nominalAirFlowRate"
    assert library["Fan"].stating_property("c1") is None
    assert library["HotWaterLoop"].stating_property("valve_flow_coefficient") == s4bldg + "flowCoefficient"
