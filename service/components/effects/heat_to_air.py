"""A constant, unmodelled heat gain (or loss) of an air stream at a component."""

from __future__ import annotations

import numpy as np

from service.components.component import (
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    MINIMUM_AIR_MASS_FLOW_KG_PER_S,
    Parameter,
    Port,
    SplicedEffect,
)

__all__ = ["ConstantHeatGain"]


class ConstantHeatGain(SplicedEffect):
    """T_out = T_in + Q / (ṁ · c_p)   [°C]

    Q a constant heat rate into the air (W, negative for a loss: casing losses, an unmodelled
    heater, a leaking bypass of conditioned air), ṁ the air mass flow (kg/s, floored at
    ``MINIMUM_AIR_MASS_FLOW_KG_PER_S``). Null: Q = 0.
    """

    inputs = (
        Port("value_in", "degC", "air temperature leaving the component"),
        Port("air_mass_flow", "kg/s", "air mass flow through the component"),
    )
    outputs = (Port("value_out", "degC", "air temperature with the heat gain"),)
    heat_rate_parameter = "heat_gain"
    parameters = (
        Parameter("heat_gain", "W", 0.0, -5000.0, 5000.0, "constant heat rate into the air stream, Q", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        flow = np.maximum(inputs["air_mass_flow"], MINIMUM_AIR_MASS_FLOW_KG_PER_S)
        return {"value_out": inputs["value_in"] + params["heat_gain"] / (flow * AIR_SPECIFIC_HEAT_J_PER_KG_K)}
