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

import math

import numpy as np
from numba import njit, vectorize

from service.components.compiled import as_row, member_value
from service.components.component import (
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    WATER_DENSITY_KG_PER_M3,
    WATER_SPECIFIC_HEAT_J_PER_KG_K,
    ComponentModel,
    Parameter,
    Port,
)
from service.components.heat_exchanger import (
    REFERENCE_AIR_MASS_FLOW,
    TINY,
    film_ua_scalar,
    heat_rate_scalar,
)

__all__ = ["HotWaterLoop", "REFERENCE_WATER_MASS_FLOW", "SUPPLY_PIPE_TANKS", "advance_tank_chain", "valve_flow_share"]

#: Opening [m³/h] at or below which the valve passes no water.
_SHUT_OPENING = 1e-6
#: Reference water flow of the water-side film conductance hA_w, kg/s (hA_a: REFERENCE_AIR_MASS_FLOW).
REFERENCE_WATER_MASS_FLOW = 0.5
#: Mixed tanks in series standing for the supply pipe's plug flow: a front arrives spread over
#: τ/√N of its transport time τ.
SUPPLY_PIPE_TANKS = 12


@njit(cache=True)
def _valve_share(position: float, rangeability: float) -> float:
    """φ(u) = R^(u−1) − (1−u)/R [1]: the valve's flow coefficient at stem position ``position`` u (0–1)
    as a share of the fully open one, for ``rangeability`` R ≥ 1 (R = 1 linear, φ(0) = 0, φ(1) = 1,
    increasing in u)."""
    return rangeability ** (position - 1.0) - (1.0 - position) / rangeability


#: :func:`_valve_share` over arrays (a numpy ufunc: broadcasts).
valve_flow_share = vectorize(["float64(float64, float64)"], cache=True)(_valve_share)


@njit(cache=True)
def _water_mass_flow(position: float, kv: float, rangeability: float, kv_loop: float, pressure_bar: float) -> float:
    """ṁ_w [kg/s] at the clipped valve position u (module docstring): V̇ [m³/h] through the opening
    K_v·φ(u) in series with K_v,loop under Δp_loop [bar]; none at an opening of 10⁻⁶ m³/h or less."""
    opening = _valve_share(position, rangeability) * kv
    if opening <= _SHUT_OPENING:
        return 0.0
    resistance = 1.0 / opening**2 + 1.0 / kv_loop**2
    return WATER_DENSITY_KG_PER_M3 * math.sqrt(np.maximum(pressure_bar, 0.0) / resistance) / 3600.0


@njit(cache=True)
def _steady_chain(entering_excess: float, transport: float, loss: float, steady) -> None:
    """The steady excesses of :func:`_advance_chain`'s tanks into ``steady`` [N]: θ_i* = θ_0·(k/(k + λ))^i,
    i = 1 … N, for θ_0 ``entering_excess`` [K], ``transport`` k and ``loss`` λ (rates, or both times dt)."""
    share = transport / (transport + loss)
    value = entering_excess
    for i in range(steady.shape[0]):
        value *= share
        steady[i] = value


@njit(cache=True)
def _advance_chain(excess, entering_excess: float, transport_dt: float, loss_dt: float, advanced, scratch) -> None:
    """One member's tanks in series, dθ_i/dt = k·(θ_{i−1} − θ_i) − λ·θ_i with θ_0 held over the step,
    advanced exactly into ``advanced``: with a = k·dt and x = (k + λ)·dt, the steady state
    θ_i* (:func:`_steady_chain`) and

        θ_i(t+dt) = θ_i* + Σ_{j≤i} w_{i−j}·(θ_j(t) − θ_j*),   w_m = e^{−x}·a^m/m!

    (the chain's matrix exponential). ``excess`` [N] the tanks' temperatures above their
    surroundings [K], ``entering_excess`` θ_0, ``transport_dt`` a, ``loss_dt`` λ·dt; ``scratch``
    [3, N] working space."""
    weights, departure, steady = scratch[0], scratch[1], scratch[2]
    _steady_chain(entering_excess, transport_dt, loss_dt, steady)
    weight = math.exp(-(transport_dt + loss_dt))
    for i in range(excess.shape[0]):
        weights[i] = weight
        weight *= transport_dt / (i + 1.0)
        departure[i] = excess[i] - steady[i]
        total = steady[i]
        for j in range(i + 1):
            total += weights[i - j] * departure[j]
        advanced[i] = total


@njit(cache=True)
def advance_tank_chain(excess, entering_excess, transport_dt, loss_dt):
    """:func:`_advance_chain` for every member: ``excess`` [n, N], the others [n] (or [1])."""
    advanced, scratch = np.empty_like(excess), np.empty((3, excess.shape[1]))
    for m in range(excess.shape[0]):
        _advance_chain(excess[m], member_value(entering_excess, m), member_value(transport_dt, m),
                       member_value(loss_dt, m), advanced[m], scratch)
    return advanced


@njit(cache=True)
def _moved_water(temperature: float, entering: float, transport: float, loss: float, surroundings: float,
                 dt_s: float) -> float:
    """Water temperature [°C] after ``dt_s`` of dT/dt = k·(T_entering − T) + (T_amb − T)/τ_loss, with
    ``transport`` k = (ṁ_w/ṁ_ref)/τ and ``loss`` 1/τ_loss [1/s], exact for inputs held over the step;
    ``temperature`` NaN: its steady state."""
    rate = transport + loss
    steady = (transport * entering + loss * surroundings) / rate
    return steady if math.isnan(temperature) else steady + (temperature - steady) * math.exp(-rate * dt_s)


@njit(cache=True)
def _loop_step(valve_position, supply_water, inlet_air, air_flow_in, params, pipe_excess, heat_rate, outlet_air,
               outlet_water, dt_s: float, start: bool):
    """The loop over one step for every member (module docstring), or its steady start when ``start``
    (the pipe and the water side in steady state, the lags at their targets). The inputs [n] or [1];
    ``params`` [12, n] or [12, 1], rows in the order of :attr:`HotWaterLoop.parameters`. Returns new
    arrays: (supply pipe excess [n, N], heat rate, outlet air, outlet water, inlet water, water mass
    flow, position)."""
    n = pipe_excess.shape[0]
    tanks = pipe_excess.shape[1]
    new_pipe, scratch = np.empty_like(pipe_excess), np.empty((3, tanks))
    heat_out, air_out, water_out = np.empty(n), np.empty(n), np.empty(n)
    water_in_out, flow_out, position_out = np.empty(n), np.empty(n), np.empty(n)
    for m in range(n):
        position = np.minimum(np.maximum(member_value(valve_position, m), 0.0), 1.0)
        supply, air_in = member_value(supply_water, m), member_value(inlet_air, m)
        air_flow = np.maximum(member_value(air_flow_in, m), 0.0)
        kv, rangeability = member_value(params[0], m), member_value(params[1], m)
        kv_loop, pressure = member_value(params[2], m), member_value(params[3], m)
        surroundings, loss = member_value(params[10], m), 1.0 / member_value(params[11], m)
        water_flow = _water_mass_flow(position, kv, rangeability, kv_loop, pressure)
        ratio = water_flow / REFERENCE_WATER_MASS_FLOW
        entering = supply - surroundings
        transport = tanks * ratio / member_value(params[6], m)
        if start:
            _steady_chain(entering, transport, loss, new_pipe[m])
        else:
            _advance_chain(pipe_excess[m], entering, transport * dt_s, loss * dt_s, new_pipe[m], scratch)
        water_in = surroundings + new_pipe[m, tanks - 1]
        ua = film_ua_scalar(member_value(params[4], m), ratio, member_value(params[5], m),
                            air_flow / REFERENCE_AIR_MASS_FLOW)
        c_water = np.maximum(water_flow * WATER_SPECIFIC_HEAT_J_PER_KG_K, TINY)
        c_air = np.maximum(air_flow * AIR_SPECIFIC_HEAT_J_PER_KG_K, TINY)
        static = heat_rate_scalar(ua, c_water, c_air, water_in, air_in) if water_flow > 0.0 else 0.0
        low, high = np.minimum(air_in, water_in), np.maximum(air_in, water_in)
        if start:
            heat = static
            air = np.minimum(np.maximum(air_in + heat / c_air, low), high)
            previous_water = math.nan
        else:
            previous = heat_rate[m]
            heat = previous + (1.0 - math.exp(-dt_s / member_value(params[7], m))) * (static - previous)
            air_target = np.minimum(np.maximum(air_in + heat / c_air, low), high)
            air = outlet_air[m] + (1.0 - math.exp(-dt_s / member_value(params[8], m))) * (air_target - outlet_air[m])
            previous_water = outlet_water[m]
        water_target = np.minimum(np.maximum(water_in - heat / c_water, low), high)
        water_out[m] = _moved_water(previous_water, water_target, ratio / member_value(params[9], m), loss,
                                    surroundings, dt_s)
        heat_out[m], air_out[m], water_in_out[m] = heat, air, water_in
        flow_out[m], position_out[m] = water_flow, position
    return new_pipe, heat_out, air_out, water_out, water_in_out, flow_out, position_out


class HotWaterLoop(ComponentModel):
    """Heating coil + motorised valve + check valve + pump (see the module docstring)."""

    air_heat_sign = 1
    valve_characteristic = ("valve_rangeability",)

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
        # the time constants of stored water and heat: set by construction, they do not drift
        Parameter("supply_pipe_time_constant", "s", 90.0, 10.0, 900.0, "supply pipe to coil inlet, τ_pipe",
                  drifts=False),
        Parameter("metal_time_constant", "s", 180.0, 60.0, 900.0, "coil metal, τ_metal", drifts=False),
        Parameter("air_side_time_constant", "s", 30.0, 5.0, 300.0, "air side, τ_a", drifts=False),
        Parameter("water_side_time_constant", "s", 60.0, 5.0, 600.0, "water side at 0.5 kg/s, τ_w", drifts=False),
        Parameter("pipe_surroundings_temperature", "degC", 18.0, 0.0, 35.0,
                  "what water standing in the pipes cools or warms to, T_amb"),
        Parameter("standing_water_time_constant", "s", 14400.0, 1800.0, 43200.0,
                  "heat loss of standing water to its surroundings, τ_loss"),
    )
    states = ("supply_pipe_water_excess", "heat_rate", "outlet_air_temperature", "outlet_water_temperature")
    #: A day: every state forgets its start at least as fast as standing water (τ_loss ≤ 12 h leaves
    #: e⁻² of a wrong start), and the states start in steady state with the first inputs.
    settling_s = 86400.0

    @classmethod
    def valve_flow_share(cls, position, params):
        """φ(u) of the valve's inherent characteristic (:func:`_valve_share`) at its rangeability."""
        return float(_valve_share(min(max(float(position), 0.0), 1.0), float(params["valve_rangeability"])))

    @staticmethod
    def _inputs(inputs) -> list[np.ndarray]:
        """The compiled step's inputs, one-dimensional float arrays in the order of :attr:`inputs`."""
        return [as_row(inputs[port.name]) for port in HotWaterLoop.inputs]

    @staticmethod
    def _parameters(params, state) -> np.ndarray:
        """The parameters as the compiled step takes them, [12, n]: packed once and kept in ``state``;
        a row is copied again where its parameter comes as another array (one that changes over
        time comes anew every step)."""
        given = [params[spec.name] for spec in HotWaterLoop.parameters]
        if "_parameters" not in state:
            rows = [as_row(values) for values in given]
            width = max(len(row) for row in rows)
            state["_parameters"] = (given, np.array([np.broadcast_to(row, width) for row in rows]))
            return state["_parameters"][1]
        kept, packed = state["_parameters"]
        for row, (values, before) in enumerate(zip(given, kept)):
            if values is not before:
                packed[row] = values
                kept[row] = values
        return packed

    def initial_state(self, params, inputs, dt_s):
        state = {}
        signals, values = self._inputs(inputs), self._parameters(params, state)
        n = max(max(len(a) for a in signals), values.shape[1])
        empty = np.full(n, np.nan)
        pipe, heat, air, water, *_ = _loop_step(*signals, values, np.empty((n, SUPPLY_PIPE_TANKS)), empty, empty,
                                                empty, float(dt_s), True)
        return state | {"supply_pipe_water_excess": pipe, "heat_rate": heat, "outlet_air_temperature": air,
                        "outlet_water_temperature": water}

    def step(self, params, inputs, state, dt_s):
        # each state is replaced by a new array, never changed in place: the outputs share them
        pipe, heat, air, water, water_in, flow, position = _loop_step(
            *self._inputs(inputs), self._parameters(params, state), state["supply_pipe_water_excess"],
            state["heat_rate"], state["outlet_air_temperature"], state["outlet_water_temperature"], float(dt_s), False)
        state.update(supply_pipe_water_excess=pipe, heat_rate=heat, outlet_air_temperature=air,
                     outlet_water_temperature=water)
        return {
            "outlet_air_temperature": air,
            "inlet_water_temperature": water_in,
            "outlet_water_temperature": water,
            "water_mass_flow": flow,
            "heat_rate": heat,
            "valve_position": position,
        }
