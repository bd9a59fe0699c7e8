"""Heat exchange between an air duct (or a unit casing) and its surroundings."""

from __future__ import annotations

import numpy as np

from service.components.component import (
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    MINIMUM_AIR_MASS_FLOW_KG_PER_S,
    Parameter,
    Port,
    SplicedEffect,
)

__all__ = ["DuctHeatExchange"]


class DuctHeatExchange(SplicedEffect):
    """T_out = T_amb + (T_in − T_amb) · exp(−UA / (ṁ · c_p))   [°C]

    The steady-state solution for air flowing through a duct of overall conductance UA (W/K) to
    surroundings at T_amb (outdoor air, return air or a room, whichever sensor the signature
    finds), ṁ floored at ``MINIMUM_AIR_MASS_FLOW_KG_PER_S``. Null: UA = 0.
    """

    inputs = (
        Port("value_in", "degC", "air temperature entering the duct"),
        Port("ambient_temperature", "degC", "temperature of the duct's surroundings"),
        Port("air_mass_flow", "kg/s", "air mass flow through the duct"),
    )
    outputs = (Port("value_out", "degC", "air temperature leaving the duct"),)
    parameters = (
        Parameter("duct_conductance", "W/K", 0.0, 0.0, 500.0, "overall duct-to-surroundings conductance, UA", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        flow = np.maximum(inputs["air_mass_flow"], MINIMUM_AIR_MASS_FLOW_KG_PER_S)
        kept = np.exp(-params["duct_conductance"] / (flow * AIR_SPECIFIC_HEAT_J_PER_KG_K))
        ambient = inputs["ambient_temperature"]
        return {"value_out": ambient + (inputs["value_in"] - ambient) * kept}
