"""Water coils driven by a logged valve command (heating and cooling): static ε-NTU.

    v = clip((u − u₀)/(1 − u₀), 0, 1),   ṁ_w = v·ṁ_w,max                               [1, kg/s]
    1/UA = 1/(hA_w·v^0.8) + 1/(hA_a·(ṁ_a/2 kg/s)^0.8)                                 [K/W]
    Q = ε(NTU, C_r)·C_min·(T_w − T_a,in),   T_a,out = T_a,in + Q/C_a                    [W, °C]

u the valve command, u₀ the actuator's dead band, T_w the supply water temperature (read from a
sensor upstream of the valve where the graph has one, else a parameter); counter-flow ε-NTU of
:mod:`service.components.heat_exchanger`, sensible heat only. Parameters (5, or 4 with T_w measured):
T_w, ṁ_w,max, hA_w, hA_a, u₀; the heating and cooling coils differ only in the prior of T_w. The
valve's position (its stem, read by a position sensor) is the command received.
Details: ``docs/components.md``.
"""

from __future__ import annotations

import numpy as np

from service.components.actuator import DEAD_BAND_PARAMETER, actuator_stem_position
from service.components.component import (
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    WATER_SPECIFIC_HEAT_J_PER_KG_K,
    ComponentModel,
    Parameter,
    Port,
)
from service.components.heat_exchanger import (
    REFERENCE_AIR_MASS_FLOW,
    TINY,
    coil_heat_rate_w,
    series_film_ua_w_per_k,
)

__all__ = ["WaterCoil", "HeatingWaterCoil", "CoolingWaterCoil"]

_FLOW_AND_CONDUCTANCES = (
    Parameter("maximum_water_mass_flow", "kg/s", 0.4, 0.02, 3.0, "water flow with the valve fully open, ṁ_w,max"),
    Parameter("water_side_conductance", "W/K", 2000.0, 100.0, 10000.0, "water-side hA with the valve fully open, hA_w"),
    Parameter("air_side_conductance", "W/K", 2000.0, 100.0, 10000.0, "air-side hA at 2 kg/s of air, hA_a"),
    Parameter("valve_dead_band", "1", 0.0, 0.0, 0.4, "command below which the valve stays shut, u₀"),
)


class WaterCoil(ComponentModel):
    """Static water-to-air coil driven by its valve command (module docstring)."""

    inputs = (
        Port("valve_position", "1", "valve command, u (0–1)"),
        Port("inlet_air_temperature", "degC", "air temperature entering the coil, T_a,in"),
        Port("air_mass_flow", "kg/s", "air mass flow through the coil, ṁ_a"),
        Port("supply_water_temperature", "degC", "water temperature entering the valve, T_w",
             fallback_parameter="supply_water_temperature"),
    )
    outputs = (
        Port("outlet_air_temperature", "degC", "air temperature leaving the coil, T_a,out"),
        Port("heat_rate", "W", "heat given to the air (negative when cooling), Q"),
        Port("valve_position", "1", "valve position reached (the stem's position feedback)", reports="valve_position"),
    )
    parameters = (
        Parameter("supply_water_temperature", "degC", 45.0, 2.0, 90.0, "water temperature entering the coil, T_w"),
    ) + _FLOW_AND_CONDUCTANCES

    def step(self, params, inputs, state, dt_s):
        opening = actuator_stem_position(inputs["valve_position"], params[DEAD_BAND_PARAMETER])
        air_in = inputs["inlet_air_temperature"]
        air_flow = np.maximum(inputs["air_mass_flow"], 0.0)
        c_air = air_flow * AIR_SPECIFIC_HEAT_J_PER_KG_K
        c_water = opening * params["maximum_water_mass_flow"] * WATER_SPECIFIC_HEAT_J_PER_KG_K
        ua = series_film_ua_w_per_k(
            water_conductance_w_per_k=params["water_side_conductance"], water_flow_ratio=opening,
            air_conductance_w_per_k=params["air_side_conductance"], air_flow_ratio=air_flow / REFERENCE_AIR_MASS_FLOW,
        )
        heat = coil_heat_rate_w(ua, water_capacity_w_per_k=c_water, air_capacity_w_per_k=c_air,
                                water_inlet_temperature=self.input_or_fallback("supply_water_temperature", inputs, params),
                                air_inlet_temperature=air_in) * (opening > 0.0)
        return {"outlet_air_temperature": air_in + heat / np.maximum(c_air, TINY), "heat_rate": heat,
                "valve_position": inputs["valve_position"]}


class HeatingWaterCoil(WaterCoil):
    """A :class:`WaterCoil` fed with hot water: T_w 35–90 °C (low-temperature to conventional boiler
    and district-heating supply), default 60 °C."""

    air_heat_sign = 1

    parameters = (
        Parameter("supply_water_temperature", "degC", 60.0, 35.0, 90.0,
                  "hot water temperature entering the coil, T_w"),
    ) + _FLOW_AND_CONDUCTANCES


class CoolingWaterCoil(WaterCoil):
    """A :class:`WaterCoil` fed with chilled water: T_w 4–18 °C (ice-storage to high-temperature
    chilled water), default 7 °C."""

    air_heat_sign = -1

    parameters = (
        Parameter("supply_water_temperature", "degC", 7.0, 4.0, 18.0,
                  "chilled water temperature entering the coil, T_w"),
    ) + _FLOW_AND_CONDUCTANCES
