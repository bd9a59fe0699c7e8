"""A water coil driven by a logged valve command (heating or cooling), static."""

from __future__ import annotations

import numpy as np

from .component import AIR_SPECIFIC_HEAT_J_PER_KG_K, WATER_SPECIFIC_HEAT_J_PER_KG_K, ComponentModel, Parameter, Port
from .hot_water_loop import counterflow_effectiveness

__all__ = ["WaterCoil"]

_TINY = 1e-9


class WaterCoil(ComponentModel):
    """Q = ε·C_min·(T_w − T_a,in),  T_a,out = T_a,in + Q/C_a   [W, °C]

    The valve command u (0–1, linear valve with constant pressure difference) sets the water flow
    ṁ_w = u·ṁ_w,max; the supply water temperature T_w is a parameter (the logged data of a BMS rarely
    holds it); counter-flow ε-NTU with UA scaled by the water flow, UA = UA_max·(u)^0.8 (water-side
    film dominated). Used for heating coils (T_w above the air) and cooling coils (T_w below: Q < 0;
    condensation is ignored, so latent cooling appears as a model error on humid days). Static: the
    coil's thermal mass is the CoilThermalMass effect, which the diagnosis can add.
    """

    inputs = (
        Port("valve_position", "1", "valve command, u"),
        Port("inlet_air_temperature", "degC", "air temperature entering the coil"),
        Port("air_mass_flow", "kg/s", "air mass flow through the coil"),
    )
    outputs = (
        Port("outlet_air_temperature", "degC", "air temperature leaving the coil"),
        Port("heat_rate", "W", "heat given to the air (negative when cooling), Q"),
    )
    parameters = (
        Parameter("supply_water_temperature", "degC", 50.0, 2.0, 90.0, "water temperature entering the coil, T_w"),
        Parameter("maximum_water_mass_flow", "kg/s", 0.3, 0.01, 3.0, "water flow with the valve open, ṁ_w,max"),
        Parameter("maximum_ua", "W/K", 800.0, 20.0, 10000.0, "UA with the valve open, UA_max"),
    )

    def step(self, params, inputs, state, dt_s):
        position = np.minimum(np.maximum(inputs["valve_position"], 0.0), 1.0)
        air_in = inputs["inlet_air_temperature"]
        c_air = np.maximum(inputs["air_mass_flow"], _TINY) * AIR_SPECIFIC_HEAT_J_PER_KG_K
        c_water = np.maximum(position * params["maximum_water_mass_flow"] * WATER_SPECIFIC_HEAT_J_PER_KG_K, _TINY)
        ua = params["maximum_ua"] * np.maximum(position, _TINY) ** 0.8
        c_min, c_max = np.minimum(c_air, c_water), np.maximum(c_air, c_water)
        heat = counterflow_effectiveness(ua / c_min, c_min / c_max) * c_min * (params["supply_water_temperature"] - air_in)
        heat = heat * (position > 0.0)
        return {"outlet_air_temperature": air_in + heat / np.maximum(c_air, 0.1 * AIR_SPECIFIC_HEAT_J_PER_KG_K),
                "heat_rate": heat}
