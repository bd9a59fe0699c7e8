"""Fan motor and drive losses carried into the air stream."""

from __future__ import annotations

import numpy as np

from service.components.component import (
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    MINIMUM_AIR_MASS_FLOW_KG_PER_S,
    Parameter,
    Port,
    SplicedEffect,
)

__all__ = ["FanMotorHeat"]


class FanMotorHeat(SplicedEffect):
    """T_out = T_in + f_tot · P / (ṁ · c_p)   [°C]

    P the fan's electric power (W), ṁ the air mass flow (kg/s, floored at
    ``MINIMUM_AIR_MASS_FLOW_KG_PER_S``), f_tot the share of the power that heats the air stream
    (1 for a motor in the air stream, its efficiency losses only for a motor outside; ASHRAE
    Handbook Fundamentals ch. 18). Null: f_tot = 0.
    """

    inputs = (
        Port("value_in", "degC", "air temperature leaving the fan without motor heat"),
        Port("electric_power", "W", "fan electric power"),
        Port("air_mass_flow", "kg/s", "air mass flow through the fan"),
    )
    outputs = (Port("value_out", "degC", "air temperature leaving the fan"),)
    parameters = (
        Parameter("motor_heat_fraction", "1", 0.0, 0.0, 1.0, "share of fan power heating the air, f_tot", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        flow = np.maximum(inputs["air_mass_flow"], MINIMUM_AIR_MASS_FLOW_KG_PER_S)
        rise = params["motor_heat_fraction"] * inputs["electric_power"] / (flow * AIR_SPECIFIC_HEAT_J_PER_KG_K)
        return {"value_out": inputs["value_in"] + rise}
