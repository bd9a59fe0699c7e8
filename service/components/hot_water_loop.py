"""Hot-water heating coil with its motorised valve, check valve and pump (Bjørnskov, Jradi & Wetter, Sec. 5.1).

Hydraulics: V̇ = sqrt(Δp_loop / (1/(K_v·u)² + 1/K_v,loop²)) [m³/h, bar], ṁ_w = ρ_w·V̇/3600 [kg/s].
Heat: counter-flow ε-NTU, Q_static = ε·C_min·(T_w,in − T_a,in) [W], with
1/UA = 1/(hA_w·(ṁ_w/0.5)^0.8) + 1/(hA_a·(ṁ_a/2)^0.8) [K/W] (:mod:`service.components.heat_exchanger`).
Dynamics: exact first-order lags for the supply pipe (stretched at low flow), the coil metal and the
air- and water-side outlet temperatures, each advanced before it is reported. Parameters (9): K_v
(mapped from ``s4bldg:flowCoefficient``), Δp_loop, K_v,loop, hA_w, hA_a and four time constants.
Equations, bounds and why these parameter groups: ``docs/components.md``.
"""

from __future__ import annotations

import numpy as np

from service.components.component import (
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    WATER_DENSITY_KG_PER_M3,
    WATER_SPECIFIC_HEAT_J_PER_KG_K,
    ComponentModel,
    Parameter,
    Port,
    first_order_lag_factor,
)
from service.components.heat_exchanger import REFERENCE_AIR_MASS_FLOW, coil_heat_rate_w, series_film_ua_w_per_k

__all__ = ["HotWaterLoop", "loop_water_flow_m3_per_h", "REFERENCE_WATER_MASS_FLOW"]

_TINY = 1e-9
#: Reference water flow of the water-side film conductance hA_w, kg/s (hA_a: REFERENCE_AIR_MASS_FLOW).
REFERENCE_WATER_MASS_FLOW = 0.5


def loop_water_flow_m3_per_h(position: np.ndarray, *, kv_valve: np.ndarray, kv_loop: np.ndarray,
                             pressure_bar: np.ndarray) -> np.ndarray:
    """V̇ [m³/h] of the series loop for valve position ``position`` (0–1, linear characteristic): the
    valve's K_v·u [m³/h] in series with ``kv_loop`` [m³/h] under ``pressure_bar`` [bar]."""
    opening = np.minimum(np.maximum(position, 0.0), 1.0) * kv_valve
    resistance = 1.0 / np.maximum(opening, _TINY) ** 2 + 1.0 / kv_loop**2
    return np.sqrt(np.maximum(pressure_bar, 0.0) / resistance) * (opening > 1e-6)


class HotWaterLoop(ComponentModel):
    """Heating coil + motorised valve + check valve + pump (see the module docstring)."""

    inputs = (
        Port("valve_position", "1", "motorised valve position commanded by the controller, u"),
        Port("supply_water_temperature", "degC", "water temperature from the heat source"),
        Port("inlet_air_temperature", "degC", "air temperature entering the coil, T_a,in"),
        Port("air_mass_flow", "kg/s", "air mass flow through the coil, ṁ_a"),
    )
    outputs = (
        Port("outlet_air_temperature", "degC", "air temperature leaving the coil"),
        Port("inlet_water_temperature", "degC", "water temperature entering the coil (after the pump)"),
        Port("outlet_water_temperature", "degC", "water temperature leaving the coil"),
        Port("water_mass_flow", "kg/s", "water mass flow, ṁ_w"),
        Port("heat_rate", "W", "heat given to the air, Q"),
        Port("valve_position", "1", "valve position reached"),
    )
    parameters = (
        Parameter("valve_flow_coefficient", "m3/h", 2.5, 0.3, 40.0, "motorised valve flow coefficient, K_v"),
        Parameter("loop_flow_coefficient", "m3/h", 3.3, 0.5, 40.0, "check valve, pipes and coil in series, K_v,loop"),
        Parameter("loop_pressure_difference", "bar", 0.45, 0.05, 1.5, "pump rise plus source–sink difference, Δp_loop"),
        Parameter("water_side_conductance", "W/K", 1600.0, 300.0, 6000.0, "water-side hA at 0.5 kg/s, hA_w"),
        Parameter("air_side_conductance", "W/K", 1600.0, 300.0, 6000.0, "air-side hA at 2 kg/s, hA_a"),
        Parameter("supply_pipe_time_constant", "s", 90.0, 10.0, 900.0, "supply pipe to coil inlet, τ_pipe"),
        Parameter("metal_time_constant", "s", 180.0, 60.0, 900.0, "coil metal, τ_metal"),
        Parameter("air_side_time_constant", "s", 30.0, 5.0, 300.0, "air side, τ_a"),
        Parameter("water_side_time_constant", "s", 60.0, 5.0, 600.0, "water side, τ_w"),
    )
    states = ("inlet_water_temperature", "heat_rate", "outlet_air_temperature", "outlet_water_temperature")
    #: Five times the four lags in series at their slowest (their time constants' upper bounds).
    settling_s = 5.0 * sum(p.upper for p in parameters if p.unit == "s")

    def _water_flow(self, params, position):
        flow_m3_per_h = loop_water_flow_m3_per_h(
            position, kv_valve=params["valve_flow_coefficient"], kv_loop=params["loop_flow_coefficient"],
            pressure_bar=params["loop_pressure_difference"],
        )
        return WATER_DENSITY_KG_PER_M3 * flow_m3_per_h / 3600.0

    def _static_heat(self, params, air_in, air_flow, water_flow, water_in):
        """Q_static [W], C_w and C_a [W/K], the capacity rates floored at 10⁻⁹ W/K (module docstring)."""
        ua = series_film_ua_w_per_k(
            water_conductance_w_per_k=params["water_side_conductance"],
            water_flow_ratio=water_flow / REFERENCE_WATER_MASS_FLOW,
            air_conductance_w_per_k=params["air_side_conductance"], air_flow_ratio=air_flow / REFERENCE_AIR_MASS_FLOW,
        )
        c_water = np.maximum(water_flow * WATER_SPECIFIC_HEAT_J_PER_KG_K, _TINY)
        c_air = np.maximum(air_flow * AIR_SPECIFIC_HEAT_J_PER_KG_K, _TINY)
        heat = coil_heat_rate_w(ua, water_capacity_w_per_k=c_water, air_capacity_w_per_k=c_air,
                                water_inlet_temperature=water_in, air_inlet_temperature=air_in) * (water_flow > 0.0)
        return heat, c_water, c_air

    def _pipe_factor(self, params, water_flow, dt_s):
        """1 − exp(−Δt/(τ_pipe·stretch)); τ_pipe ≥ 10 s by its bounds, so no zero guard is needed."""
        stretch = REFERENCE_WATER_MASS_FLOW / np.maximum(water_flow, 0.05)
        return -np.expm1(-dt_s / (params["supply_pipe_time_constant"] * stretch))

    def initial_state(self, params, inputs, dt_s):
        shape = np.broadcast(inputs["supply_water_temperature"], params["air_side_conductance"]).shape
        supply = np.broadcast_to(inputs["supply_water_temperature"], shape).astype(float)
        air_in = np.broadcast_to(inputs["inlet_air_temperature"], shape).astype(float)
        water_flow = self._water_flow(params, np.clip(inputs["valve_position"], 0.0, 1.0))
        heat, c_water, c_air = self._static_heat(params, air_in, np.maximum(inputs["air_mass_flow"], 0.0), water_flow, supply)
        low, high = np.minimum(air_in, supply), np.maximum(air_in, supply)
        return {
            # lag factors of the constant time constants, computed once per run
            "_metal_factor": first_order_lag_factor(dt_s, params["metal_time_constant"]) + 0.0 * supply,
            "_air_factor": first_order_lag_factor(dt_s, params["air_side_time_constant"]) + 0.0 * supply,
            "_water_factor": first_order_lag_factor(dt_s, params["water_side_time_constant"]) + 0.0 * supply,
            "inlet_water_temperature": supply.copy(),
            "heat_rate": heat + 0.0 * supply,
            "outlet_air_temperature": np.clip(air_in + heat / c_air, low, high),
            "outlet_water_temperature": np.where(water_flow > 0.0, np.clip(supply - heat / c_water, low, high), air_in),
        }

    def step(self, params, inputs, state, dt_s):
        air_in = inputs["inlet_air_temperature"]
        air_flow = np.maximum(inputs["air_mass_flow"], 0.0)
        position = np.minimum(np.maximum(inputs["valve_position"], 0.0), 1.0)
        water_flow = self._water_flow(params, position)
        water_in = state["inlet_water_temperature"]
        water_in += self._pipe_factor(params, water_flow, dt_s) * (inputs["supply_water_temperature"] - water_in)
        heat_static, c_water, c_air = self._static_heat(params, air_in, air_flow, water_flow, water_in)
        heat = state["heat_rate"]
        heat += state["_metal_factor"] * (heat_static - heat)
        low, high = np.minimum(air_in, water_in), np.maximum(air_in, water_in)
        # T_a,out = T_a,in + Q/(ṁ_a·c_p), the same C_a as the heat rate's (energy balance); clipped to
        # [T_a,in, T_w,in]: stagnant air (fan off) in a warm coil approaches the water temperature
        air_target = np.minimum(np.maximum(air_in + heat / c_air, low), high)
        water_target = np.where(water_flow > 0.0, np.minimum(np.maximum(water_in - heat / c_water, low), high), air_in)
        air_out = state["outlet_air_temperature"]
        air_out += state["_air_factor"] * (air_target - air_out)
        water_out = state["outlet_water_temperature"]
        water_out += state["_water_factor"] * (water_target - water_out)
        return {
            "outlet_air_temperature": air_out.copy(),
            "inlet_water_temperature": water_in.copy(),
            "outlet_water_temperature": water_out.copy(),
            "water_mass_flow": water_flow,
            "heat_rate": heat.copy(),
            "valve_position": position,
        }
