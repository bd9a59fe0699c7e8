"""Supply fan driven by a speed command (VFD): air flow from speed, power from the part-load curve."""

from __future__ import annotations

import numpy as np

from .component import AIR_DENSITY_KG_PER_M3, ComponentModel, Parameter, Port
from .fan import Fan, part_load_power_fraction

__all__ = ["SpeedControlledFan"]


class SpeedControlledFan(ComponentModel):
    """V̇ = s·V̇_nom (fan laws at constant system curve), ṁ = ρ·V̇, P = P_nom·(c1 + c2·s + c3·s² + c4·s³)

    s the speed command (0–1, clipped); the air leaves at its inlet temperature (motor heat is the
    FanMotorHeat effect). Parameters and bounds as :class:`service.fan.Fan`.
    """

    inputs = (
        Port("speed", "1", "fan speed command, s"),
        Port("inlet_air_temperature", "degC", "air temperature at the fan inlet"),
    )
    outputs = Fan.outputs
    parameters = Fan.parameters

    def step(self, params, inputs, state, dt_s):
        speed = np.minimum(np.maximum(inputs["speed"], 0.0), 1.0)
        flow = speed * params["nominal_air_flow"]
        power = params["nominal_power"] * part_load_power_fraction(speed, params["c1"], params["c2"], params["c3"], params["c4"])
        return {"outlet_air_temperature": inputs["inlet_air_temperature"],
                "outlet_air_mass_flow": AIR_DENSITY_KG_PER_M3 * flow, "electric_power": power}
