"""Water coils driven by a logged valve command (heating and cooling): static ε-NTU.

A building automation system logs the valve *command* of each coil but rarely the water side, so the
coil's water flow follows from the command and its supply water temperature is a parameter::

    v = clip((u − u₀)/(1 − u₀), 0, 1)                                                 [1]
    ṁ_w = v · ṁ_w,max                                                              [kg/s]
    1/UA = 1/(hA_w · v^0.8) + 1/(hA_a · (ṁ_a/ṁ_a,ref)^0.8),   ṁ_a,ref = 2 kg/s        [K/W]
    Q = ε(NTU, C_r) · C_min · (T_w − T_a,in)      (counter-flow, :mod:`service.components.heat_exchanger`)
    T_a,out = T_a,in + Q / C_a                                                        [°C]

u the valve command (0–1), v the valve's opening: a linear valve at constant differential pressure
(flow ∝ v) whose actuator starts to move only above the command u₀ (its dead band: a 2–10 V actuator
on a 0–10 V output has u₀ = 0.2; u₀ = 0 an ideal actuator). C_w = ṁ_w·c_p,w, C_a = ṁ_a·c_p,a; hA_w
is the water-side film conductance with the valve fully open, hA_a the air-side one at 2 kg/s of
air. v = 0 gives no flow and no heat (T_a,out = T_a,in); with no air flow the stagnant air takes the
water temperature (ε → 1).

A controller holds a command inside the dead band while the coil need not heat (the FLEXLAB X3A
logs 0.1–0.3 on September nights with no heat reaching the supply air), so a coil model without it
can fit such data only with a coil that cannot heat at all.

Static: the coil's thermal mass is the CoilThermalMass effect the diagnosis can add. A cooling coil
gives Q < 0; condensation is ignored (sensible heat only: the air's humidity is not an input), so
a wet coil's behaviour shows as a model error or is absorbed by the calibrated conductances.

**Parameters (5)**: T_w, ṁ_w,max, hA_w, hA_a, u₀. Bounds are those of the coils of a 0.2–3 m³/s air
handling unit. :class:`HeatingWaterCoil` (hot water, 35–90 °C) and :class:`CoolingWaterCoil`
(chilled water, 4–18 °C) differ from :class:`WaterCoil` (whose service the graph does not state:
2–90 °C) only in the prior of T_w.
"""

from __future__ import annotations

import numpy as np

from service.components.component import AIR_SPECIFIC_HEAT_J_PER_KG_K, WATER_SPECIFIC_HEAT_J_PER_KG_K, ComponentModel, Parameter, Port
from service.components.heat_exchanger import REFERENCE_AIR_MASS_FLOW, coil_heat_rate_w, series_film_ua_w_per_k

__all__ = ["WaterCoil", "HeatingWaterCoil", "CoolingWaterCoil"]

_TINY = 1e-9

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
    )
    outputs = (
        Port("outlet_air_temperature", "degC", "air temperature leaving the coil, T_a,out"),
        Port("heat_rate", "W", "heat given to the air (negative when cooling), Q"),
    )
    parameters = (
        Parameter("supply_water_temperature", "degC", 45.0, 2.0, 90.0, "water temperature entering the coil, T_w"),
    ) + _FLOW_AND_CONDUCTANCES

    def step(self, params, inputs, state, dt_s):
        dead_band = params["valve_dead_band"]
        opening = np.minimum(np.maximum((inputs["valve_position"] - dead_band) / (1.0 - dead_band), 0.0), 1.0)
        air_in = inputs["inlet_air_temperature"]
        air_flow = np.maximum(inputs["air_mass_flow"], 0.0)
        c_air = air_flow * AIR_SPECIFIC_HEAT_J_PER_KG_K
        c_water = opening * params["maximum_water_mass_flow"] * WATER_SPECIFIC_HEAT_J_PER_KG_K
        ua = series_film_ua_w_per_k(
            params["water_side_conductance"], opening,
            params["air_side_conductance"], air_flow / REFERENCE_AIR_MASS_FLOW,
        )
        heat = coil_heat_rate_w(ua, c_water, c_air, params["supply_water_temperature"], air_in) * (opening > 0.0)
        return {"outlet_air_temperature": air_in + heat / np.maximum(c_air, _TINY), "heat_rate": heat}


class HeatingWaterCoil(WaterCoil):
    """A :class:`WaterCoil` fed with hot water: T_w 35–90 °C (low-temperature to conventional boiler
    and district-heating supply), default 60 °C."""

    parameters = (
        Parameter("supply_water_temperature", "degC", 60.0, 35.0, 90.0,
                  "hot water temperature entering the coil, T_w"),
    ) + _FLOW_AND_CONDUCTANCES


class CoolingWaterCoil(WaterCoil):
    """A :class:`WaterCoil` fed with chilled water: T_w 4–18 °C (ice-storage to high-temperature
    chilled water), default 7 °C."""

    parameters = (
        Parameter("supply_water_temperature", "degC", 7.0, 4.0, 18.0,
                  "chilled water temperature entering the coil, T_w"),
    ) + _FLOW_AND_CONDUCTANCES
