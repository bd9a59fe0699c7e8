"""Sensors and the BMS trend: additive Gaussian noise and quantisation for temperatures, noise in
proportion to the reading for power and flow, a first-order response, and sampling from the
simulation step to the data step as instantaneous samples or interval means."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SensorSpec", "SENSORS", "read", "sample_instant", "sample_mean"]


@dataclass(frozen=True, kw_only=True)
class SensorSpec:
    """A sensor: noise σ absolute (``sigma``, in the reading's unit) or relative (``relative_sigma``,
    a fraction of the reading), quantum of the stored value, response time constant (s) and whether
    the trend stores the value at the stamp or the mean over the interval before it."""

    sigma: float = 0.0
    relative_sigma: float = 0.0
    quantum: float = 0.0
    tau_s: float = 0.0
    mean: bool = False


SENSORS: dict[str, SensorSpec] = {
    "fan_inlet_air_temperature": SensorSpec(sigma=0.15, quantum=0.1, tau_s=20.0),
    "supply_air_flow": SensorSpec(relative_sigma=0.02, quantum=0.001, mean=True),
    "supply_fan_power": SensorSpec(relative_sigma=0.02, quantum=1.0, mean=True),
    "coil_outlet_air_temperature": SensorSpec(sigma=0.15, quantum=0.1, tau_s=20.0),
    "supply_water_temperature": SensorSpec(sigma=0.15, quantum=0.1, tau_s=30.0),
    "valve_position": SensorSpec(sigma=0.003, quantum=0.001),
    "coil_inlet_water_temperature": SensorSpec(sigma=0.15, quantum=0.1, tau_s=30.0),
    "coil_outlet_water_temperature": SensorSpec(sigma=0.15, quantum=0.1, tau_s=30.0),
    "coil_outlet_air_temperature_setpoint": SensorSpec(),
}


def read(values: np.ndarray, spec: SensorSpec, rng: np.random.Generator) -> np.ndarray:
    """The stored readings of sampled true ``values``: noise, then quantisation."""
    noisy = values + spec.sigma * rng.standard_normal(values.size) \
        + spec.relative_sigma * np.abs(values) * rng.standard_normal(values.size)
    return np.round(noisy / spec.quantum) * spec.quantum if spec.quantum > 0 else noisy


def sample_instant(values: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """The value at each stamp's simulation index."""
    return values[stamps]


def sample_mean(values: np.ndarray, stamps: np.ndarray, per_sample: int) -> np.ndarray:
    """The mean over the ``per_sample`` simulation steps ending at each stamp's index."""
    cumulative = np.concatenate([[0.0], np.cumsum(values)])
    return (cumulative[stamps + 1] - cumulative[stamps + 1 - per_sample]) / per_sample
