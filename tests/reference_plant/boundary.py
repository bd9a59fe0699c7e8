"""What the plant is given: weather, the heat-recovery stage upstream of the fan, the occupancy
schedule, the supply-air flow and setpoint schedules and the supply water temperature.

Times are seconds from the simulation start ``t_s``; ``weekday`` 0 = Monday. Temperatures in °C,
flows in m³/s. Weather noise is an AR(1) (Ornstein–Uhlenbeck) process sampled at the step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

__all__ = ["Schedule", "Weather", "BoundaryConditions", "boundary_conditions", "ornstein_uhlenbeck",
           "first_order_filter"]


def ornstein_uhlenbeck(n: int, dt_s: float, sigma: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` samples of a stationary AR(1) process of standard deviation ``sigma`` and correlation
    time ``tau_s``: x_k = a·x_{k−1} + σ·√(1 − a²)·w_k, a = exp(−Δt/τ)."""
    a = np.exp(-dt_s / tau_s)
    shocks = sigma * np.sqrt(1.0 - a * a) * rng.standard_normal(n)
    shocks[0] = sigma * rng.standard_normal()
    return lfilter([1.0], [1.0, -a], shocks)


def first_order_filter(x: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """τ·dy/dt = x − y, exact for x held over each step, starting in steady state (y₀ = x₀)."""
    if tau_s <= 0.0:
        return np.asarray(x, dtype=float).copy()
    a = np.exp(-dt_s / tau_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    return y


@dataclass(frozen=True, kw_only=True)
class Weather:
    """Outdoor air: a daily sinusoid (coldest at 03:00, warmest at 15:00) around a mean that wanders
    from day to day, plus fast weather noise."""

    mean_c: float = 1.0
    daily_amplitude_k: float = 4.0
    day_to_day_sigma_k: float = 2.5
    noise_sigma_k: float = 0.8
    noise_tau_s: float = 3 * 3600.0


@dataclass(frozen=True, kw_only=True)
class Schedule:
    """Operation: occupied on weekdays ``occupied_from_h``–``occupied_to_h``. Supply air flow as a
    fraction of nominal (occupied: a demand-controlled level wandering around ``occupied_flow``;
    otherwise a reduced flow, lower at weekends), the VSD ramping with time constant ``fan_ramp_s``.
    Coil outlet air setpoint in steps: day, night, weekend setback."""

    occupied_from_h: float = 6.0
    occupied_to_h: float = 18.0
    occupied_flow: float = 0.85
    occupied_flow_sigma: float = 0.08
    night_flow: float = 0.40
    weekend_flow: float = 0.30
    fan_ramp_s: float = 60.0
    day_setpoint_c: float = 20.0
    night_setpoint_c: float = 17.0
    weekend_setpoint_c: float = 16.0


@dataclass(frozen=True, kw_only=True)
class BoundaryConditions:
    """The plant's inputs on the simulation grid (arrays of one length)."""

    outdoor_c: np.ndarray
    extract_c: np.ndarray
    fan_inlet_c: np.ndarray  # after the heat recovery
    flow_fraction: np.ndarray  # supply air flow / nominal
    setpoint_c: np.ndarray
    supply_water_c: np.ndarray
    occupied: np.ndarray


def _occupancy(t_s: np.ndarray, start_weekday: int, schedule: Schedule) -> tuple[np.ndarray, np.ndarray]:
    day = np.floor(t_s / 86400.0).astype(int)
    hour = (t_s - 86400.0 * day) / 3600.0
    weekend = (start_weekday + day) % 7 >= 5
    occupied = ~weekend & (hour >= schedule.occupied_from_h) & (hour < schedule.occupied_to_h)
    return occupied, weekend


def boundary_conditions(t_s: np.ndarray, *, start_weekday: int, start_hour: float, rng: np.random.Generator,
                        weather: Weather, schedule: Schedule, recovery_effectiveness: float = 0.8,
                        supply_water_reset: tuple[float, float, float, float] = (-10.0, 62.0, 15.0, 38.0),
                        supply_water_noise_k: float = 0.6) -> BoundaryConditions:
    """The inputs at times ``t_s`` (s, the grid starting at ``start_hour`` of a day, ``start_weekday``).

    Heat recovery: a balanced counter-flow recuperator, ε = NTU/(1 + NTU), NTU ∝ flow^−0.2 (film
    coefficients ∝ flow^0.8), ``recovery_effectiveness`` at nominal flow; T_in = T_oa + ε·(T_ex − T_oa).
    Supply water: outdoor-reset line through (T_oa, T_sw) = ``supply_water_reset`` (two points,
    clipped at its ends) of the 1-hour mean outdoor temperature, plus boiler-cycling noise.
    """
    dt_s = float(t_s[1] - t_s[0])
    n = t_s.size
    clock_s = t_s + 3600.0 * start_hour
    occupied, weekend = _occupancy(clock_s, start_weekday, schedule)
    day = np.floor(clock_s / 86400.0)
    day_levels = weather.day_to_day_sigma_k * rng.standard_normal(int(day.max()) + 2)
    day_mean = np.interp(clock_s / 86400.0 - 0.5, np.arange(day_levels.size), day_levels)
    hour = (clock_s % 86400.0) / 3600.0
    outdoor = (weather.mean_c + day_mean + weather.daily_amplitude_k * np.sin(2 * np.pi * (hour - 9.0) / 24.0)
               + ornstein_uhlenbeck(n, dt_s, weather.noise_sigma_k, weather.noise_tau_s, rng))

    demand = schedule.occupied_flow + ornstein_uhlenbeck(n, dt_s, schedule.occupied_flow_sigma, 1800.0, rng)
    level = np.where(occupied, np.clip(demand, 0.5, 1.0),
                     np.where(weekend, schedule.weekend_flow, schedule.night_flow))
    flow_fraction = first_order_filter(level, dt_s, schedule.fan_ramp_s)

    extract = first_order_filter(np.where(occupied, 22.0, 20.5), dt_s, 2 * 3600.0)
    ntu = recovery_effectiveness / (1.0 - recovery_effectiveness) * flow_fraction ** -0.2
    effectiveness = ntu / (1.0 + ntu)
    fan_inlet = outdoor + effectiveness * (extract - outdoor)

    setpoint = np.where(occupied, schedule.day_setpoint_c,
                        np.where(weekend, schedule.weekend_setpoint_c, schedule.night_setpoint_c))

    t_cold, w_cold, t_warm, w_warm = supply_water_reset
    outdoor_hour = first_order_filter(outdoor, dt_s, 3600.0)
    supply_water = (np.interp(outdoor_hour, [t_cold, t_warm], [w_cold, w_warm])
                    + ornstein_uhlenbeck(n, dt_s, supply_water_noise_k, 600.0, rng))
    return BoundaryConditions(outdoor_c=outdoor, extract_c=extract, fan_inlet_c=fan_inlet, flow_fraction=flow_fraction,
                              setpoint_c=setpoint, supply_water_c=supply_water, occupied=occupied)
