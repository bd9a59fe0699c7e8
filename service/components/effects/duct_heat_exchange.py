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

__all__ = ["DuctHeatExchange", "DuctHeatExchangeUnmeasured"]


def _duct_outlet_temperature(inlet_c, surroundings_c, air_mass_flow_kg_s, conductance_w_k):
    """T_out = T_amb + (T_in − T_amb) · exp(−UA / (ṁ · c_p)) [°C], ṁ floored at
    ``MINIMUM_AIR_MASS_FLOW_KG_PER_S``."""
    flow = np.maximum(air_mass_flow_kg_s, MINIMUM_AIR_MASS_FLOW_KG_PER_S)
    kept = np.exp(-conductance_w_k / (flow * AIR_SPECIFIC_HEAT_J_PER_KG_K))
    # at UA = 0 (the null) T_in itself, to the last bit: T_amb + (T_in − T_amb) rounds where the two
    # differ in magnitude (the diagnosis's shared model holds the effect at its null)
    return np.where(conductance_w_k == 0.0, inlet_c, surroundings_c + (inlet_c - surroundings_c) * kept)


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
        return {"value_out": _duct_outlet_temperature(inputs["value_in"], inputs["ambient_temperature"],
                                                      inputs["air_mass_flow"], params["duct_conductance"])}


class DuctHeatExchangeUnmeasured(SplicedEffect):
    """T_out = T_amb + (T_in − T_amb) · exp(−UA / (ṁ · c_p))   [°C], T_amb estimated

    :class:`DuctHeatExchange` where no sensor measures the surroundings (a plant room, a ceiling void,
    a roof the graph does not describe): their temperature T_amb is a constant estimated with UA,
    within −20 to 50 °C. Null: UA = 0 (T_amb then has no effect).
    """

    inputs = tuple(port for port in DuctHeatExchange.inputs if port.name != "ambient_temperature")
    outputs = DuctHeatExchange.outputs
    surroundings_temperature_parameter = "surroundings_temperature"
    parameters = DuctHeatExchange.parameters + (
        Parameter("surroundings_temperature", "degC", 20.0, -20.0, 50.0,
                  "temperature of the unmeasured surroundings, T_amb"),
    )

    def step(self, params, inputs, state, dt_s):
        return {"value_out": _duct_outlet_temperature(inputs["value_in"], params["surroundings_temperature"],
                                                      inputs["air_mass_flow"], params["duct_conductance"])}
