"""A week of varied operation of the case-study ventilation unit: the boundary inputs of synthetic data.

Days and nights, heating and none, fan speed changes and setpoint steps, so every effect is excited.
Series in SI units (°C, m³/s), keyed by the case-study sensors' ``gt:timeSeriesId``: outdoor air (a
daily sinusoid around 8 °C ± 6 K, a wandering daily mean and AR(1) weather noise), plant room air,
supply air flow (0.55 m³/s at night, 1.0–1.5 m³/s per 2-hour block by day), supply water (a heating
curve, 70 °C at −10 °C outdoor to 45 °C at +20 °C) and the coil outlet air setpoint (16/21 °C,
ventilation-only afternoons, two seeded 2 K steps). The exact profiles: ``docs/data.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.errors import InputError

__all__ = ["OperationProfile", "case_study_operation"]


@dataclass(frozen=True)
class OperationProfile:
    """Boundary series of a synthetic run: ``timestamps`` (datetime64[s]), ``step_s`` and
    ``series`` (time-series id → ndarray[n_steps], SI units)."""

    timestamps: np.ndarray
    step_s: float
    series: dict[str, np.ndarray]


def _ar1(rng: np.random.Generator, n: int, sigma: float, correlation: float) -> np.ndarray:
    noise = rng.normal(0.0, sigma * np.sqrt(1.0 - correlation**2), n)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        out[i] = correlation * out[i - 1] + noise[i]
    return out


def case_study_operation(
    n_days: float = 7.0, step_s: float = 600.0, seed: int = 0, start: str = "2026-01-12T00:00:00"
) -> OperationProfile:
    """Boundary inputs for ``n_days`` of operation at ``step_s`` (the module docstring; ``docs/data.md``)."""
    if step_s <= 0 or n_days <= 0:
        raise InputError(f"need positive n_days and step_s, got {n_days} and {step_s}")
    rng = np.random.default_rng(seed)
    n = int(round(n_days * 86400.0 / step_s))
    seconds = np.arange(n) * step_s
    timestamps = np.datetime64(start, "s") + seconds.astype("timedelta64[s]")
    hour = (seconds / 3600.0) % 24.0
    day = (seconds // 86400.0).astype(int)
    n_day = int(day.max()) + 1
    daily_mean = np.cumsum(rng.normal(0.0, 3.0, n_day))
    daily_mean += 8.0 - daily_mean.mean()
    outdoor = daily_mean[day] + 6.0 * np.sin(2.0 * np.pi * (hour - 9.0) / 24.0)
    outdoor += _ar1(rng, n, 0.3, np.exp(-step_s / 7200.0))
    occupied = (hour >= 6.0) & (hour < 22.0)
    plant_room = 16.0 + 0.4 * (outdoor - 8.0) + 1.5 * occupied
    block = (seconds // 7200.0).astype(int)
    levels = rng.choice([1.0, 1.2, 1.35, 1.5], size=int(block.max()) + 1)
    air_flow = np.where(occupied, levels[block], 0.55)
    water = np.clip(70.0 - (outdoor + 10.0) * (25.0 / 30.0), 45.0, 70.0) + rng.normal(0.0, 0.5, n)
    setpoint = np.where(occupied, 21.0, 16.0)
    ventilation_only = (day % 2 == 1) & (hour >= 13.0) & (hour < 16.0)
    setpoint = np.where(ventilation_only, 12.0, setpoint)
    for step_day in rng.choice(n_day, size=min(2, n_day), replace=False):
        morning = (day == step_day) & (hour >= 8.0) & (hour < 11.0)
        setpoint = np.where(morning, setpoint + 2.0, setpoint)
    return OperationProfile(
        timestamps=timestamps, step_s=float(step_s),
        series={
            "fan_inlet_air_temperature": outdoor,
            "plant_room_air_temperature": plant_room,
            "supply_air_flow": air_flow,
            "supply_water_temperature": water,
            "coil_outlet_air_temperature_setpoint": setpoint,
        },
    )
