"""The closed loop of the plant, simulated at a step of seconds, and its BMS trend.

Per step: the VSD fan moves the scheduled air (its impeller losses, and a motor-heat fault, heat
the air); the PI controller, sampled every ``controller_period_s``, reads the coil outlet air
sensor and commands the valve actuator, which moves at most one full stroke per ``actuator_travel_s``
(anti-windup: the integral is held while the output saturates in the error's direction); the stem
sets the valve's Kv (equal-percentage, plus a seat leak) and the circuit the water flow; the
supply water reaches the coil through a plug-flow pipe (delay = volume / flow) and the coil gives
heat to the air by ε-NTU with its metal mass; a heat gain and the casing's exchange with the
space act after the coil. The trend samples the sensors every ``data_step_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .boundary import BoundaryConditions, Schedule, Weather, boundary_conditions, first_order_filter
from .equipment import AIR_CP, AIR_DENSITY, Circuit, Coil, Fan, PlugFlowPipe, equal_percentage_kv
from .faults import FAULTS, Fault, FaultTruth
from .sensors import SENSORS, read, sample_instant, sample_mean

__all__ = ["PlantSettings", "PlantRun", "simulate_plant"]


@dataclass(frozen=True, kw_only=True)
class PlantSettings:
    """Equipment, control and trend. Kv in m³/h, volumes in m³, UA in W/K, times in s, °C."""

    fan: Fan = field(default_factory=Fan)
    circuit: Circuit = field(default_factory=Circuit)
    coil: Coil = field(default_factory=Coil)
    weather: Weather = field(default_factory=Weather)
    schedule: Schedule = field(default_factory=Schedule)
    valve_kvs_m3_h: float = 2.5
    valve_rangeability: float = 50.0
    supply_pipe_volume_m3: float = 6e-3
    supply_pipe_ua_w_per_k: float = 0.8
    return_pipe_volume_m3: float = 1e-3
    return_pipe_ua_w_per_k: float = 0.2
    space_c: float = 14.0  # the plant room around the unit and its pipes
    controller_gain_per_k: float = 0.02
    controller_integral_time_s: float = 240.0
    controller_period_s: float = 30.0
    actuator_travel_s: float = 120.0
    step_s: float = 10.0
    data_step_s: float = 600.0
    warmup_s: float = 6 * 3600.0


@dataclass(frozen=True, kw_only=True)
class PlantRun:
    """The BMS trend (``timestamps``, ``readings`` by CSV column), what was injected (``truth``) and
    true series at the data steps that no sensor shows (``hidden``: water flow m³/s, heat into the air
    and out of the water at the coil W, heat added by the fan W, valve command, true coil outlet
    air °C — interval means)."""

    timestamps: np.ndarray
    readings: dict[str, np.ndarray]
    truth: FaultTruth
    hidden: dict[str, np.ndarray]


def _active(fault: Fault | None, t_s: np.ndarray, name: str) -> np.ndarray:
    """Where on the grid fault ``name`` acts (from its start on)."""
    if fault is None or fault.name != name:
        return np.zeros(t_s.size, dtype=bool)
    return fault.active(t_s) > 0


def _fault_series(fault: Fault | None, t_s: np.ndarray, name: str) -> np.ndarray:
    """The size of fault ``name`` over the grid: its size where it acts, else 0."""
    return np.where(_active(fault, t_s, name), fault.size if fault else 0.0, 0.0)


def simulate_plant(*, days: float = 7.0, start: str = "2026-01-15T00:00", seed: int = 0, fault: Fault | None = None,
                   settings: PlantSettings | None = None, space_column: bool = False) -> PlantRun:
    """Simulate ``days`` of the plant from ``start`` (ISO date-time, local standard time) with ``fault``
    (its ``start_s`` counted from ``start``) and return the trend. ``space_column``: also trend the
    temperature of the space around the unit (``space_air_temperature``). Deterministic per ``seed``."""
    s = settings or PlantSettings()
    rng = np.random.default_rng(seed)
    origin = np.datetime64(start, "s")
    dt = s.step_s
    per_sample = round(s.data_step_s / dt)
    warm = round(s.warmup_s / dt)
    n = warm + round(days * 86400.0 / dt)
    t_s = (np.arange(n) - warm) * dt  # s from the data start
    sim_origin = origin - np.timedelta64(int(s.warmup_s), "s")
    weekday = int((sim_origin.astype("datetime64[D]").astype(int) - 4) % 7)  # 1970-01-01 was a Thursday
    hour = float((sim_origin - sim_origin.astype("datetime64[D]")).astype(int)) / 3600.0
    bc = boundary_conditions(t_s - t_s[0], start_weekday=weekday, start_hour=hour, rng=rng, weather=s.weather,
                             schedule=s.schedule)
    trace = _closed_loop(s, bc, t_s, fault, rng)

    stamps = warm + per_sample * np.arange(round(days * 86400.0 / s.data_step_s))  # a stamp's value at it,
    # its mean over the step before it
    true_values = _sensor_truth(s, bc, trace, t_s, fault)
    readings = {}
    for column, spec in SENSORS.items():
        values = true_values[column]
        sampled = sample_mean(values, stamps, per_sample) if spec.mean else sample_instant(values, stamps)
        readings[column] = read(sampled, spec, rng)
    readings["valve_position"] = np.clip(readings["valve_position"], 0.0, 1.0)
    if space_column:
        readings["space_air_temperature"] = read(np.full(stamps.size, s.space_c), SENSORS["fan_inlet_air_temperature"],
                                                 rng)
    hidden = {name: sample_mean(trace[name], stamps, per_sample)
              for name in ("water_flow_m3_s", "coil_air_heat_w", "coil_water_heat_w", "fan_heat_w", "command",
                           "coil_outlet_air_c")}
    timestamps = origin + np.round(t_s[stamps]).astype("timedelta64[s]")
    kind = FAULTS[fault.name] if fault else None
    truth = FaultTruth(fault=fault.name if fault else None, size=fault.size if fault else 0.0,
                       node=kind.node if kind else None, catalog_effect=kind.catalog_effect if kind else None,
                       start=origin + np.timedelta64(int(fault.start_s), "s") if fault else None)
    return PlantRun(timestamps=timestamps, readings=readings, truth=truth, hidden=hidden)


def _closed_loop(s: PlantSettings, bc: BoundaryConditions, t_s: np.ndarray, fault: Fault | None,
                 rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The sequential part: controller, actuator, valve, circuit, pipes, coil, controlled sensor."""
    n, dt = t_s.size, s.step_s
    air_flow = bc.flow_fraction * s.fan.nominal_flow_m3_s
    c_air = AIR_DENSITY * AIR_CP * air_flow
    power = s.fan.electric_power_w(bc.flow_fraction)
    fan_heat = s.fan.impeller_loss_w(bc.flow_fraction) + _fault_series(fault, t_s, "fan_motor_heat") * power
    coil_air_in = bc.fan_inlet_c + fan_heat / c_air
    leak_kv = _fault_series(fault, t_s, "valve_leakage") * s.valve_kvs_m3_h
    stuck_on = _active(fault, t_s, "valve_stuck")
    offset = _fault_series(fault, t_s, "sensor_offset")
    heat_gain = _fault_series(fault, t_s, "constant_heat_gain")
    casing_ua = _fault_series(fault, t_s, "duct_heat_exchange")
    casing_factor = np.exp(-casing_ua / c_air)
    capacity_factor = np.where(_active(fault, t_s, "coil_thermal_mass"), fault.size if fault else 1.0, 1.0)
    fouling_days = np.maximum(t_s - (fault.start_s if fault else 0.0), 0.0) / 86400.0
    ua_factor = (1.0 - _fault_series(fault, t_s, "coil_fouling")) ** fouling_days
    pipe_loss = _fault_series(fault, t_s, "supply_pipe_heat_loss")
    sensor_noise = SENSORS["coil_outlet_air_temperature"].sigma * rng.standard_normal(n)

    supply_pipe = PlugFlowPipe(s.supply_pipe_volume_m3, s.supply_pipe_ua_w_per_k, s.space_c, n, dt, s.space_c)
    return_pipe = PlugFlowPipe(s.return_pipe_volume_m3, s.return_pipe_ua_w_per_k, s.space_c, n, dt, s.space_c)
    names = ("stem", "command", "water_flow_m3_s", "coil_inlet_water_c", "coil_outlet_water_c", "coil_air_heat_w",
             "coil_water_heat_w", "coil_outlet_air_c", "sensed_air_c")
    out = {name: np.empty(n) for name in names}
    out["fan_heat_w"] = fan_heat
    metal = float(coil_air_in[0])
    sensed = float(coil_air_in[0])
    stem = command = integral = 0.0
    sample_every = max(1, round(s.controller_period_s / dt))
    max_move = dt / s.actuator_travel_s
    sensor_alpha = 1.0 - math.exp(-dt / SENSORS["coil_outlet_air_temperature"].tau_s)
    kp, ti, ts = s.controller_gain_per_k, s.controller_integral_time_s, sample_every * dt
    kvs, rangeability = s.valve_kvs_m3_h, s.valve_rangeability
    for k in range(n):
        if k % sample_every == 0:  # the PI controller's sample
            error = float(bc.setpoint_c[k]) - (sensed + float(offset[k]) + float(sensor_noise[k]))
            trial = integral + kp * ts / ti * error
            unclamped = kp * error + trial
            if 0.0 <= unclamped <= 1.0 or (unclamped > 1.0 and error < 0.0) or (unclamped < 0.0 and error > 0.0):
                integral = trial
            command = min(max(kp * error + integral, 0.0), 1.0)
        if stuck_on[k]:
            stem = fault.size
        else:
            stem += min(max(command - stem, -max_move), max_move)
        kv = equal_percentage_kv(stem, kvs, rangeability) + float(leak_kv[k])
        water = s.circuit.flow_m3_s(kv)
        water_in = supply_pipe.step(float(bc.supply_water_c[k]), water, float(pipe_loss[k]))
        metal, q_air, q_water, water_out = s.coil.step(
            metal, water_in, float(coil_air_in[k]), water, float(air_flow[k]), dt,
            ua_factor=float(ua_factor[k]), capacity_factor=float(capacity_factor[k]))
        air_out = float(coil_air_in[k]) + (q_air + float(heat_gain[k])) / float(c_air[k])
        air_out = s.space_c + (air_out - s.space_c) * float(casing_factor[k])
        sensed += sensor_alpha * (air_out - sensed)
        out["stem"][k], out["command"][k], out["water_flow_m3_s"][k] = stem, command, water
        out["coil_inlet_water_c"][k] = water_in
        out["coil_outlet_water_c"][k] = return_pipe.step(water_out, water)
        out["coil_air_heat_w"][k], out["coil_water_heat_w"][k] = q_air, q_water
        out["coil_outlet_air_c"][k], out["sensed_air_c"][k] = air_out, sensed
    out["power_w"] = power
    out["offset_k"] = offset
    return out


def _sensor_truth(s: PlantSettings, bc: BoundaryConditions, trace: dict[str, np.ndarray], t_s: np.ndarray,
                  fault: Fault | None) -> dict[str, np.ndarray]:
    """What each sensor element indicates on the simulation grid, before noise and the trend."""
    dt = s.step_s

    def lagged(values: np.ndarray, column: str) -> np.ndarray:
        return first_order_filter(values, dt, SENSORS[column].tau_s)

    outlet_water = lagged(trace["coil_outlet_water_c"], "coil_outlet_water_temperature")
    lagging = _active(fault, t_s, "sensor_lag")
    if lagging.any():
        slow = first_order_filter(trace["coil_outlet_water_c"], dt,
                                  SENSORS["coil_outlet_water_temperature"].tau_s + fault.size)
        outlet_water = np.where(lagging, slow, outlet_water)
    return {
        "fan_inlet_air_temperature": lagged(bc.fan_inlet_c, "fan_inlet_air_temperature"),
        "supply_air_flow": bc.flow_fraction * s.fan.nominal_flow_m3_s,
        "supply_fan_power": trace["power_w"],
        "coil_outlet_air_temperature": trace["sensed_air_c"] + trace["offset_k"],
        "supply_water_temperature": lagged(bc.supply_water_c, "supply_water_temperature"),
        "valve_position": trace["stem"],  # the stem's feedback; the BMS clips the reading to 0–1
        "coil_inlet_water_temperature": lagged(trace["coil_inlet_water_c"], "coil_inlet_water_temperature"),
        "coil_outlet_water_temperature": outlet_water,
        "coil_outlet_air_temperature_setpoint": bc.setpoint_c,
    }
