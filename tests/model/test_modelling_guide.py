"""The modelling guide's example unit (docs/modelling.md, "A unit from scratch") assembles as printed
into what the guide says it does."""

import re
from pathlib import Path

from service.graph.store import GraphStore
from service.model.assembly import assemble

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "modelling.md"
EX = "https://example.org/my-ahu#"


def test_the_guides_cooling_unit_assembles_into_what_the_guide_says():
    turtle = re.search(r"```turtle\n(.*?)```", GUIDE.read_text(), re.S).group(1)
    store = GraphStore.embedded(None)
    store.load_model("guide", turtle.encode(), "turtle")
    model = assemble(store, "guide")
    assert {c.signature.id for c in model.components.values()} >= {"SpeedControlledFan", "CoolingCoil"}
    def devices(components) -> set[str]:
        return {node.removeprefix(EX) for c in components for node in model.components[c].modeled_nodes}

    assert devices(model.boundary_inputs) == {"outdoor_air_sensor", "fan_speed_command", "valve_command"}
    assert devices(model.targets) == {"fan_power_meter", "valve_position_sensor", "supply_air_sensor"}
    assert not [n for n in model.notes if "unstated service" in n]
