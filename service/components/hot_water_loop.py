"""Hot-water heating coil with its motorised valve, check valve and pump (Bjørnskov, Jradi & Wetter, Sec. 5.1).

Hydraulics: V̇ = sqrt(Δp_loop / (1/(K_v·φ(u))² + 1/K_v,loop²)) [m³/h, bar], ṁ_w = ρ_w·V̇/3600 [kg/s],
with the valve's inherent characteristic φ(u) = R^(u−1) − (1−u)/R of rangeability R (R = 1: linear;
R ≫ 1: equal-percentage, shut tight at u = 0).
Heat: counter-flow ε-NTU, Q_static = ε·C_min·(T_w,in − T_a,in) [W], with
1/UA = 1/(hA_w·(ṁ_w/0.5)^0.8) + 1/(hA_a·(ṁ_a/2)^0.8) [K/W] (:mod:`service.components.heat_exchanger`).
Water in the supply pipe and on the water side moves with the flow and loses heat where it stands:
dT/dt = (ṁ_w/ṁ_ref)·(T_entering − T)/τ + (T_amb − T)/τ_loss, τ the transport time at the reference
flow ṁ_ref = 0.5 kg/s (τ_pipe, τ_w; hours near shut-off), advanced exactly; the supply pipe as
``SUPPLY_PIPE_TANKS`` such tanks in series (each τ_pipe/N: plug flow, a front arriving after the
transport time), the water side as one. The coil metal and the air-side outlet are first-order
lags. Parameters (12): K_v (mapped from ``s4bldg:flowCoefficient``), R, Δp_loop, K_v,loop, hA_w,
hA_a, four time constants, T_amb and τ_loss. Equations, bounds and why these parameter groups:
``docs/components.md``.
"""

from __future__ import annotations

import numpy as np
from scipy.special import gammaln

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

__all__ = ["HotWaterLoop", "REFERENCE_WATER_MASS_FLOW", "SUPPLY_PIPE_TANKS", "advance_tank_chain", "steady_tank_chain",
           "valve_flow_share"]

# 0-d arrays: numpy's ufuncs take them faster than Python floats
_TINY, _ZERO, _ONE = np.array(1e-9), np.array(0.0), np.array(1.0)
#: Opening [m³/h] at or below which the valve passes no water.
_SHUT_OPENING = np.array(1e-6)
#: Reference water flow of the water-side film conductance hA_w, kg/s (hA_a: REFERENCE_AIR_MASS_FLOW).
REFERENCE_WATER_MASS_FLOW = 0.5
#: Mixed tanks in series standing for the supply pipe's plug flow: a front arrives spread over
#: τ/√N of its transport time τ.
SUPPLY_PIPE_TANKS = 12
_TANK_POWERS = np.arange(1.0, SUPPLY_PIPE_TANKS + 1.0)
# the transport kernel's orders 0 … N−1 and one more whose weight is 0 (log m! = ∞): the Toeplitz
# matrix's upper triangle indexes it, so no mask is needed
_KERNEL_ORDER = np.arange(SUPPLY_PIPE_TANKS + 1.0)
_KERNEL_LOG_FACTORIAL = np.append(gammaln(_TANK_POWERS), np.inf)
_KERNEL_INDEX = np.subtract.outer(np.arange(SUPPLY_PIPE_TANKS), np.arange(SUPPLY_PIPE_TANKS))
_KERNEL_INDEX[_KERNEL_INDEX < 0] = SUPPLY_PIPE_TANKS


def steady_tank_chain(entering_excess: np.ndarray, transport: np.ndarray, loss: np.ndarray) -> np.ndarray:
    """The tanks' steady excesses [..., N] of :func:`advance_tank_chain`'s chain, θ_i* = θ_0·(k/(k + λ))^i,
    for ``entering_excess`` θ_0 [K], ``transport`` k and ``loss`` λ (rates, or both times one dt)."""
    share = np.asarray(transport)[..., None] / (np.asarray(transport)[..., None] + np.asarray(loss)[..., None])
    return np.asarray(entering_excess)[..., None] * share ** _TANK_POWERS


def advance_tank_chain(excess: np.ndarray, entering_excess: np.ndarray, transport_dt: np.ndarray,
                       loss_dt: np.ndarray) -> np.ndarray:
    """Tanks in series, dθ_i/dt = k·(θ_{i−1} − θ_i) − λ·θ_i with θ_0 held over the step, advanced
    exactly: with a = k·dt and x = (k + λ)·dt, the steady state θ_i* (:func:`steady_tank_chain`) and

        θ_i(t+dt) = θ_i* + Σ_{j≤i} e^{−x}·a^{i−j}/(i−j)!·(θ_j(t) − θ_j*)

    (the chain's matrix exponential). ``excess`` [..., N] the tanks' temperatures above their
    surroundings [K], ``entering_excess`` [...] the water entering, ``transport_dt`` a, ``loss_dt`` λ·dt."""
    a = np.asarray(transport_dt)[..., None]
    x = a + np.asarray(loss_dt)[..., None]
    steady = steady_tank_chain(entering_excess, transport_dt, loss_dt)
    kernel = np.exp(_KERNEL_ORDER * np.log(np.maximum(a, 1e-300)) - x - _KERNEL_LOG_FACTORIAL)
    return steady + np.matmul(kernel[..., _KERNEL_INDEX], (excess - steady)[..., None])[..., 0]


def valve_flow_share(position: np.ndarray, rangeability: np.ndarray) -> np.ndarray:
    """φ(u) = R^(u−1) − (1−u)/R [1]: the valve's flow coefficient at stem position ``position`` u (0–1)
    as a share of the fully open one, for ``rangeability`` R ≥ 1 (R = 1 linear, φ(0) = 0, φ(1) = 1,
    increasing in u)."""
    return rangeability ** (position - _ONE) - (_ONE - position) / rangeability


def _series_flow_m3_per_h(opening: np.ndarray, kv_loop: np.ndarray, pressure_bar: np.ndarray) -> np.ndarray:
    """V̇ [m³/h] through an opening K_v·φ(u) ≥ 0 [m³/h] in series with ``kv_loop`` [m³/h] under
    ``pressure_bar`` [bar] (module docstring); 0 at an opening of 10⁻⁶ m³/h or less."""
    resistance = _ONE / np.maximum(opening, _TINY) ** 2 + _ONE / kv_loop**2
    return np.sqrt(np.maximum(pressure_bar, _ZERO) / resistance) * (opening > _SHUT_OPENING)


class HotWaterLoop(ComponentModel):
    """Heating coil + motorised valve + check valve + pump (see the module docstring)."""

    air_heat_sign = 1

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
        Port("valve_position", "1", "valve position reached (the stem's position feedback)", reports="valve_position"),
    )
    parameters = (
        Parameter("valve_flow_coefficient", "m3/h", 2.5, 0.3, 40.0, "motorised valve flow coefficient, K_v"),
        Parameter("valve_rangeability", "1", 25.0, 1.0, 100.0,
                  "inherent characteristic, R: 1 linear, 25–50 an equal-percentage heating valve"),
        Parameter("loop_flow_coefficient", "m3/h", 3.3, 0.5, 40.0, "check valve, pipes and coil in series, K_v,loop"),
        Parameter("loop_pressure_difference", "bar", 0.45, 0.05, 1.5, "pump rise plus source–sink difference, Δp_loop"),
        Parameter("water_side_conductance", "W/K", 1600.0, 300.0, 6000.0, "water-side hA at 0.5 kg/s, hA_w"),
        Parameter("air_side_conductance", "W/K", 1600.0, 300.0, 6000.0, "air-side hA at 2 kg/s, hA_a"),
        Parameter("supply_pipe_time_constant", "s", 90.0, 10.0, 900.0, "supply pipe to coil inlet, τ_pipe"),
        Parameter("metal_time_constant", "s", 180.0, 60.0, 900.0, "coil metal, τ_metal"),
        Parameter("air_side_time_constant", "s", 30.0, 5.0, 300.0, "air side, τ_a"),
        Parameter("water_side_time_constant", "s", 60.0, 5.0, 600.0, "water side at 0.5 kg/s, τ_w"),
        Parameter("pipe_surroundings_temperature", "degC", 18.0, 0.0, 35.0,
                  "what water standing in the pipes cools or warms to, T_amb"),
        Parameter("standing_water_time_constant", "s", 14400.0, 1800.0, 43200.0,
                  "heat loss of standing water to its surroundings, τ_loss"),
    )
    states = ("supply_pipe_water_excess", "heat_rate", "outlet_air_temperature", "outlet_water_temperature")
    #: A day: every state forgets its start at least as fast as standing water (τ_loss ≤ 12 h leaves
    #: e⁻² of a wrong start), and the states start in steady state with the first inputs.
    settling_s = 86400.0

    def _water_flow(self, params, position):
        """ṁ_w [kg/s] at valve position ``position``, already clipped to 0–1."""
        opening = valve_flow_share(position, params["valve_rangeability"]) * params["valve_flow_coefficient"]
        flow_m3_per_h = _series_flow_m3_per_h(opening, params["loop_flow_coefficient"],
                                              params["loop_pressure_difference"])
        return WATER_DENSITY_KG_PER_M3 * flow_m3_per_h / 3600.0

    def _static_heat(self, params, air_in, air_flow, water_flow, water_flow_ratio, water_in):
        """Q_static [W], C_w and C_a [W/K], the capacity rates floored at 10⁻⁹ W/K (module docstring);
        ``water_flow_ratio`` = ṁ_w/ṁ_ref."""
        ua = series_film_ua_w_per_k(
            water_conductance_w_per_k=params["water_side_conductance"], water_flow_ratio=water_flow_ratio,
            air_conductance_w_per_k=params["air_side_conductance"], air_flow_ratio=air_flow / REFERENCE_AIR_MASS_FLOW,
        )
        c_water = np.maximum(water_flow * WATER_SPECIFIC_HEAT_J_PER_KG_K, _TINY)
        c_air = np.maximum(air_flow * AIR_SPECIFIC_HEAT_J_PER_KG_K, _TINY)
        heat = coil_heat_rate_w(ua, water_capacity_w_per_k=c_water, air_capacity_w_per_k=c_air,
                                water_inlet_temperature=water_in, air_inlet_temperature=air_in) * (water_flow > _ZERO)
        return heat, c_water, c_air

    @staticmethod
    def _standing_loss(params):
        """1/τ_loss [1/s] and T_amb/τ_loss [K/s] of water standing in the pipes."""
        loss = _ONE / params["standing_water_time_constant"]
        return loss, loss * params["pipe_surroundings_temperature"]

    @staticmethod
    def _moved_water(temperature, entering, transport, loss, loss_drive, dt_s):
        """Water temperature [°C] after ``dt_s`` of dT/dt = k·(T_entering − T) + (T_amb − T)/τ_loss, with
        ``transport`` k = (ṁ_w/ṁ_ref)/τ [1/s] and ``loss``, ``loss_drive`` from :meth:`_standing_loss`
        (module docstring), exact for inputs held over the step; ``temperature`` None: its steady state."""
        rate = transport + loss
        steady = (transport * entering + loss_drive) / rate
        return steady if temperature is None else steady + (temperature - steady) * np.exp(rate * -dt_s)

    def initial_state(self, params, inputs, dt_s):
        shape = np.broadcast(inputs["supply_water_temperature"], params["air_side_conductance"]).shape
        supply = np.broadcast_to(inputs["supply_water_temperature"], shape).astype(float)
        air_in = np.broadcast_to(inputs["inlet_air_temperature"], shape).astype(float)
        water_flow = self._water_flow(params, np.clip(inputs["valve_position"], 0.0, 1.0))
        water_ratio = water_flow / REFERENCE_WATER_MASS_FLOW
        loss, loss_drive = self._standing_loss(params)
        surroundings = params["pipe_surroundings_temperature"]
        pipe_excess = steady_tank_chain(supply - surroundings,
                                        SUPPLY_PIPE_TANKS * water_ratio / params["supply_pipe_time_constant"], loss)
        water_in = surroundings + pipe_excess[..., -1]
        heat, c_water, c_air = self._static_heat(params, air_in, np.maximum(inputs["air_mass_flow"], 0.0),
                                                 water_flow, water_ratio, water_in)
        low, high = np.minimum(air_in, water_in), np.maximum(air_in, water_in)
        water_target = np.clip(water_in - heat / c_water, low, high)
        return {
            # lag factors of the constant time constants, computed once per run
            "_metal_factor": first_order_lag_factor(dt_s, params["metal_time_constant"]) + 0.0 * supply,
            "_air_factor": first_order_lag_factor(dt_s, params["air_side_time_constant"]) + 0.0 * supply,
            "supply_pipe_water_excess": pipe_excess + 0.0 * supply[..., None],
            "heat_rate": heat + 0.0 * supply,
            "outlet_air_temperature": np.clip(air_in + heat / c_air, low, high),
            "outlet_water_temperature": self._moved_water(
                None, water_target, water_ratio / params["water_side_time_constant"], loss, loss_drive, dt_s,
            ) + 0.0 * supply,
        }

    def step(self, params, inputs, state, dt_s):
        # each state is replaced by a new array, never changed in place: the outputs share them
        air_in = inputs["inlet_air_temperature"]
        air_flow = np.maximum(inputs["air_mass_flow"], _ZERO)
        position = np.minimum(np.maximum(inputs["valve_position"], _ZERO), _ONE)
        water_flow = self._water_flow(params, position)
        water_ratio = water_flow / REFERENCE_WATER_MASS_FLOW
        loss, loss_drive = self._standing_loss(params)
        surroundings = params["pipe_surroundings_temperature"]
        pipe_excess = state["supply_pipe_water_excess"] = advance_tank_chain(
            state["supply_pipe_water_excess"], inputs["supply_water_temperature"] - surroundings,
            SUPPLY_PIPE_TANKS * dt_s * water_ratio / params["supply_pipe_time_constant"], loss * dt_s)
        water_in = surroundings + pipe_excess[..., -1]
        heat_static, c_water, c_air = self._static_heat(params, air_in, air_flow, water_flow, water_ratio, water_in)
        heat = state["heat_rate"]
        heat = state["heat_rate"] = heat + state["_metal_factor"] * (heat_static - heat)
        low, high = np.minimum(air_in, water_in), np.maximum(air_in, water_in)
        # T_a,out = T_a,in + Q/(ṁ_a·c_p), the same C_a as the heat rate's (energy balance); clipped to
        # [T_a,in, T_w,in]: stagnant air (fan off) in a warm coil approaches the water temperature
        air_target = np.minimum(np.maximum(air_in + heat / c_air, low), high)
        water_target = np.minimum(np.maximum(water_in - heat / c_water, low), high)
        air_out = state["outlet_air_temperature"]
        air_out = state["outlet_air_temperature"] = air_out + state["_air_factor"] * (air_target - air_out)
        water_out = state["outlet_water_temperature"] = self._moved_water(
            state["outlet_water_temperature"], water_target, water_ratio / params["water_side_time_constant"],
            loss, loss_drive, dt_s)
        return {
            "outlet_air_temperature": air_out,
            "inlet_water_temperature": water_in,
            "outlet_water_temperature": water_out,
            "water_mass_flow": water_flow,
            "heat_rate": heat,
            "valve_position": position,
        }
