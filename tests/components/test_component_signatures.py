"""Every component signature fits its model: each input mapped, port units match the quantities."""

import pytest

from service.components.library import SignatureLibrary, load_model_class
from service.components.measuring_device import MeasuringDevice

#: Simulator unit of each quantity (signatures/README.md).
QUANTITY_UNITS = {"temperature": "degC", "mass_flow": "kg/s", "volume_flow": "m3/s", "power": "W",
                  "position": "1", "heat_rate": "W"}
COMPONENTS = sorted((s for s in SignatureLibrary.load().values() if s.kind == "component"),
                    key=lambda s: s.id)


@pytest.mark.parametrize("signature", COMPONENTS, ids=lambda s: s.id)
def test_signature_wires_every_input_with_the_port_units(signature):
    cls = load_model_class(signature)
    mapped_inputs = {m.port for m in signature.inputs}
    if issubclass(cls, MeasuringDevice):
        assert mapped_inputs <= {"measured_value"}  # none: a boundary device (schedule, command)
    else:
        assert mapped_inputs == set(cls.input_names()), "an unmapped input would be fed NaN"
    assert {m.port for m in signature.outputs} <= set(cls.output_names())
    for mapping in signature.inputs + signature.outputs:
        assert mapping.quantity in QUANTITY_UNITS, mapping
        unit = cls.port(mapping.port).unit
        assert unit in ("", QUANTITY_UNITS[mapping.quantity]), (mapping, unit)
    for mapping in signature.parameters:
        cls.parameter(mapping.name)  # raises KeyError naming the parameter
        assert signature.nodes[mapping.node].literal


def test_heating_cooling_and_unstated_coils_select_their_supply_water_priors():
    library = SignatureLibrary.load()
    gt = "https://w3id.org/graphtwin/ontology#"
    priors = {}
    for sid, coil_class in (("HeatingCoil", gt + "HeatingCoil"), ("CoolingCoil", gt + "CoolingCoil"),
                            ("WaterCoil", "https://saref.etsi.org/saref4bldg/Coil")):
        signature = library[sid]
        assert signature.nodes["coil"].classes == (coil_class,)
        spec = load_model_class(signature).parameter("supply_water_temperature")
        priors[sid] = (spec.lower, spec.upper)
    assert priors["CoolingCoil"][1] < priors["HeatingCoil"][0]
    assert priors["WaterCoil"][0] <= priors["CoolingCoil"][0] and priors["WaterCoil"][1] >= priors["HeatingCoil"][1]
