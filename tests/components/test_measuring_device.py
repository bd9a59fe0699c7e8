"""Measuring device: replays what it receives; its signatures say which quantity each kind carries."""

import numpy as np

from service.components.library import load_signature
from service.components.measuring_device import MeasuringDevice
from service.resources import signatures_dir


def test_passes_any_value_through_unchanged(run_model):
    values = np.array([-12.5, 0.0, 19.25, 1e5, np.nan])
    out = run_model(MeasuringDevice, {}, {"measured_value": values})[0]["measured_value"]
    np.testing.assert_array_equal(out, values)


def test_each_device_kind_carries_the_quantity_it_observes():
    """One model, six signatures that differ by what the device observes (signatures/README.md)."""
    kinds = {
        "temperature_sensor": ("gt:TemperatureSensor", "temperature"),
        "flow_meter": ("gt:FlowSensor", "volume_flow"),
        "power_meter": ("gt:PowerMeter", "power"),
        "position_sensor": ("gt:PositionSensor", "position"),
        "setpoint_schedule": ("gt:SetpointSchedule", "temperature"),
        "command_signal": ("gt:CommandSignal", "position"),
    }
    gt = "https://w3id.org/graphtwin/ontology#"
    for name, (device_class, quantity) in kinds.items():
        signature = load_signature(signatures_dir() / f"{name}.toml")
        assert signature.model == "service.components.measuring_device:MeasuringDevice", name
        (device,) = signature.modeled_nodes
        assert signature.nodes[device].classes == (gt + device_class.split(":")[1],), name
        assert [(o.port, o.quantity) for o in signature.outputs] == [("measured_value", quantity)], name
        # a measured input, when there is one, carries the same quantity from upstream
        assert all((i.port, i.quantity) == ("measured_value", quantity) for i in signature.inputs), name
        # every triple optional: a device with nothing modelled upstream still matches (a boundary input)
        assert all(t.is_optional for t in signature.triples), name
