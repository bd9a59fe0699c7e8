"""The plant's equipment, from first principles: the VSD supply fan, the two-way valve and its
hydraulic circuit (pump, coil, check valve), and the counter-flow heating coil.

Units: flows in m³/s (air) and m³/h (water, where a valve's Kv is), pressures in bar (water) and Pa
(air), powers in W, temperatures in °C, heat capacity rates C = ṁ·c_p in W/K.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["AIR_DENSITY", "AIR_CP", "WATER_DENSITY", "WATER_CP", "Fan", "Circuit", "Coil",
           "PlugFlowPipe", "equal_percentage_kv",
           "counter_flow_effectiveness"]

AIR_DENSITY = 1.20  # kg/m³, at about 20 °C
AIR_CP = 1006.0  # J/(kg·K)
WATER_DENSITY = 985.0  # kg/m³, at about 55 °C
WATER_CP = 4180.0  # J/(kg·K)


@dataclass(frozen=True, kw_only=True)
class Fan:
    """A VSD fan on a duct system with a constant static-pressure part: Δp = Δp_fix + (Δp_n − Δp_fix)·x²
    (x = flow / nominal), air power V·Δp, impeller efficiency η_f = η_fn·(1 − 0.25·(1 − x)²), motor and
    drive efficiency falling at part load, η_md = η_mdn·(1 − exp(−L/0.03)) with L the shaft-load
    fraction. Electric power scaled to ``nominal_power_w`` at nominal flow: P ≈ cubic in flow plus
    a linear part. ``impeller_heat_share``: the impeller's losses heat the air inside the unit."""

    nominal_flow_m3_s: float = 1.5
    nominal_power_w: float = 1800.0
    nominal_pressure_pa: float = 600.0
    fixed_pressure_pa: float = 30.0
    impeller_efficiency: float = 0.65
    motor_drive_efficiency: float = 0.80

    def _shaft_and_electric(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.clip(x, 0.0, None)
        pressure = self.fixed_pressure_pa + (self.nominal_pressure_pa - self.fixed_pressure_pa) * x * x
        air_power = x * self.nominal_flow_m3_s * pressure
        shaft = air_power / (self.impeller_efficiency * (1.0 - 0.25 * (1.0 - x) ** 2))
        nominal_shaft = self.nominal_flow_m3_s * self.nominal_pressure_pa / self.impeller_efficiency
        load = shaft / nominal_shaft
        electric = shaft / (self.motor_drive_efficiency * (1.0 - np.exp(-np.maximum(load, 1e-6) / 0.03)))
        nominal_electric = nominal_shaft / (self.motor_drive_efficiency * (1.0 - math.exp(-1.0 / 0.03)))
        scale = self.nominal_power_w / nominal_electric
        return shaft * scale, electric * scale

    def electric_power_w(self, flow_fraction: np.ndarray) -> np.ndarray:
        return self._shaft_and_electric(np.asarray(flow_fraction, dtype=float))[1]

    def impeller_loss_w(self, flow_fraction: np.ndarray) -> np.ndarray:
        """Shaft power not turned into air power: it heats the air in the unit (W)."""
        x = np.asarray(flow_fraction, dtype=float)
        shaft, _ = self._shaft_and_electric(x)
        return shaft * (1.0 - self.impeller_efficiency * (1.0 - 0.25 * (1.0 - x) ** 2))


def equal_percentage_kv(stem: float, kvs: float, rangeability: float = 50.0) -> float:
    """Inherent characteristic of an equal-percentage valve closing tight at stem 0: Kv = Kvs·(R^(h−1)
    − (1 − h)/R), h the stem position 0 … 1, Kv in m³/h (flow at 1 bar across the valve)."""
    h = min(max(stem, 0.0), 1.0)
    return kvs * (rangeability ** (h - 1.0) - (1.0 - h) / rangeability)


@dataclass(frozen=True, kw_only=True)
class Circuit:
    """The coil's water circuit: a constant-speed pump, Δp_pump = H₀·(1 − (Q/Q₀)²); the coil and pipes,
    Δp = k·Q²; a check valve opening at ``check_valve_cracking_bar``; the control valve, Δp = (Q/Kv)².
    With Q in m³/h and Δp in bar the loop closes at Q = Kv·√((H₀ − Δp_c)/(1 + Kv²·(k + H₀/Q₀²))):
    the valve's authority follows from the circuit rather than being given."""

    pump_shutoff_bar: float = 0.40
    pump_free_flow_m3_h: float = 2.5
    coil_and_pipe_k_bar_per_m3_h2: float = 0.067
    check_valve_cracking_bar: float = 0.02

    def flow_m3_s(self, kv_m3_h: float) -> float:
        head = self.pump_shutoff_bar - self.check_valve_cracking_bar
        if kv_m3_h <= 0.0 or head <= 0.0:
            return 0.0
        resistance = self.coil_and_pipe_k_bar_per_m3_h2 + self.pump_shutoff_bar / self.pump_free_flow_m3_h ** 2
        return kv_m3_h * math.sqrt(head / (1.0 + kv_m3_h * kv_m3_h * resistance)) / 3600.0

    def authority(self, kvs: float) -> float:
        """Valve authority: Δp across the open valve / Δp across it when shut (the available head)."""
        q = self.flow_m3_s(kvs) * 3600.0
        return (q / kvs) ** 2 / (self.pump_shutoff_bar - self.check_valve_cracking_bar)


def counter_flow_effectiveness(ntu: float, capacity_ratio: float) -> float:
    """ε of a counter-flow exchanger: (1 − e^{−NTU(1−Cr)}) / (1 − Cr·e^{−NTU(1−Cr)}), NTU/(1 + NTU) at Cr = 1."""
    if abs(1.0 - capacity_ratio) < 1e-6:
        return ntu / (1.0 + ntu)
    e = math.exp(-ntu * (1.0 - capacity_ratio))
    return (1.0 - e) / (1.0 - capacity_ratio * e)


@dataclass(frozen=True, kw_only=True)
class Coil:
    """A hot-water heating coil: counter-flow ε-NTU for the quasi-steady heat rate, film conductances
    hA ∝ flow^0.8 on both sides (1/UA = 1/hA_air + 1/hA_water), and a lumped metal (plus water content)
    heat capacity ``metal_capacity_j_per_k`` between them:

        C_m·dT_m/dt = (hA_w + hA_a)·(T_m,ss − T_m),   T_m,ss = (hA_w·T̄_w + hA_a·T̄_a)/(hA_w + hA_a)

    (T̄ the fluids' mean temperatures at steady state); the heat the metal stores is taken from the
    water and the air in proportion to their conductances, so energy is conserved."""

    nominal_ua_w_per_k: float = 2500.0
    air_to_water_conductance_ratio: float = 0.25  # hA_air / hA_water at nominal flows
    nominal_air_flow_m3_s: float = 1.5
    nominal_water_flow_m3_s: float = 0.30e-3
    metal_capacity_j_per_k: float = 35_000.0

    def conductances(self, air_flow_m3_s: float, water_flow_m3_s: float, ua_factor: float = 1.0) -> tuple[float, float]:
        """(hA_air, hA_water) in W/K."""
        r = self.air_to_water_conductance_ratio
        ha_air_n = self.nominal_ua_w_per_k * (1.0 + r) / r
        ha_water_n = self.nominal_ua_w_per_k * (1.0 + r)
        ha_air = ua_factor * ha_air_n * (max(air_flow_m3_s, 0.0) / self.nominal_air_flow_m3_s) ** 0.8
        ha_water = ua_factor * ha_water_n * (max(water_flow_m3_s, 0.0) / self.nominal_water_flow_m3_s) ** 0.8
        return ha_air, ha_water

    def step(self, metal_c: float, water_in_c: float, air_in_c: float, water_flow_m3_s: float,
             air_flow_m3_s: float, dt_s: float, *, ua_factor: float = 1.0,
             capacity_factor: float = 1.0) -> tuple[float, float, float, float]:
        """One step: (metal temperature after, heat into the air W, heat out of the water W, water
        outlet temperature °C)."""
        c_air = AIR_DENSITY * AIR_CP * max(air_flow_m3_s, 0.0)
        c_water = WATER_DENSITY * WATER_CP * water_flow_m3_s
        ha_air, ha_water = self.conductances(air_flow_m3_s, water_flow_m3_s, ua_factor)
        if c_water > 1e-9 and c_air > 1e-9:
            ua = 1.0 / (1.0 / ha_air + 1.0 / ha_water)
            c_min, c_max = min(c_air, c_water), max(c_air, c_water)
            q_steady = counter_flow_effectiveness(ua / c_min, c_min / c_max) * c_min * (water_in_c - air_in_c)
            water_mean = water_in_c - 0.5 * q_steady / c_water
            air_mean = air_in_c + 0.5 * q_steady / c_air
        else:
            q_steady, water_mean, air_mean = 0.0, metal_c, air_in_c
        conductance = ha_air + ha_water
        if conductance <= 0.0:
            return metal_c, 0.0, 0.0, metal_c
        metal_steady = (ha_water * water_mean + ha_air * air_mean) / conductance
        capacity = self.metal_capacity_j_per_k * capacity_factor
        metal_after = metal_steady + (metal_c - metal_steady) * math.exp(-dt_s * conductance / capacity)
        stored = capacity * (metal_after - metal_c) / dt_s
        q_air = q_steady - stored * ha_air / conductance
        q_water = q_steady + stored * ha_water / conductance
        water_out = water_in_c - q_water / c_water if c_water > 1e-9 else metal_after
        low, high = min(water_in_c, air_in_c, metal_c), max(water_in_c, air_in_c, metal_c)
        return metal_after, q_air, q_water, min(max(water_out, low), high)


class PlugFlowPipe:
    """Water moving through a pipe of ``volume_m3`` as a plug: what leaves at step k entered when the
    volume pumped since was the pipe's volume, so the transport delay is volume / flow (hours near
    shut-off). On its way each parcel loses heat to surroundings at ``ambient_c`` through the pipe's
    conductance ``ua_w_per_k``: T = T_amb + (T_entered − T_amb)·exp(−age·UA/(ρ·c·V)).
    Sequential: :meth:`step` once per simulation step."""

    def __init__(self, volume_m3: float, ua_w_per_k: float, ambient_c: float, n_steps: int, dt_s: float,
                 initial_c: float):
        self.volume_m3 = volume_m3
        self.ambient_c = ambient_c
        self.dt_s = dt_s
        self._loss_per_s = ua_w_per_k / (WATER_DENSITY * WATER_CP * volume_m3)
        self._pumped = np.zeros(n_steps + 1)  # volume pumped before step k enters
        self._entered = np.zeros(n_steps)
        self._initial_c = initial_c
        self._oldest = 0
        self._k = 0

    def step(self, inlet_c: float, flow_m3_s: float, extra_ua_w_per_k: float = 0.0) -> float:
        """The outlet temperature (°C) at this step, ``inlet_c`` entering with ``flow_m3_s``."""
        k = self._k
        self._entered[k] = inlet_c
        self._pumped[k + 1] = self._pumped[k] + flow_m3_s * self.dt_s
        leaving = self._pumped[k + 1] - self.volume_m3  # the parcel leaving entered at this pumped volume
        if leaving < 0.0:
            entered_c, age_s = self._initial_c, (k + 1) * self.dt_s
        else:
            while self._pumped[self._oldest + 1] <= leaving:
                self._oldest += 1
            entered_c, age_s = self._entered[self._oldest], (k + 1 - self._oldest) * self.dt_s
        self._k = k + 1
        loss = self._loss_per_s + extra_ua_w_per_k / (WATER_DENSITY * WATER_CP * self.volume_m3)
        return self.ambient_c + (entered_c - self.ambient_c) * math.exp(-age_s * loss)
