"""ε-NTU relations shared by the water-to-air coils: counter-flow effectiveness, flow-dependent UA.

C = ṁ·c_p [W/K], NTU = UA/C_min, C_r = C_min/C_max; the heat rate from the water to the air is
Q = ε(NTU, C_r)·C_min·(T_w,in − T_a,in) [W] (Incropera & DeWitt, *Fundamentals of Heat and Mass
Transfer*, Sec. 11.4). A finned multi-row coil is a pure counter-flow exchanger (ASHRAE Handbook –
HVAC Systems and Equipment, Ch. 23) whose UA is the series of the two film conductances, each
∝ ṁ^0.8 (Dittus–Boelter; the tube wall's resistance neglected)::

    1/UA = 1/(hA_w · (ṁ_w/ṁ_w,ref)^0.8) + 1/(hA_a · (ṁ_a/ṁ_a,ref)^0.8)            [K/W]

Each relation is a compiled scalar function (``*_scalar``, called by the compiled steps of
:mod:`service.components.hot_water_loop`) and, over arrays, a numpy ufunc made from it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, vectorize

__all__ = [
    "FILM_EXPONENT", "REFERENCE_AIR_MASS_FLOW", "counterflow_effectiveness", "series_film_ua_w_per_k",
    "coil_heat_rate_w", "effectiveness_scalar", "film_ua_scalar", "heat_rate_scalar",
]

#: Exponent of the film conductance's dependence on the mass flow (Dittus–Boelter, Re^0.8).
FILM_EXPONENT = 0.8
#: Reference air flow at which the coils' air-side film conductance hA_a is quoted, kg/s (the
#: nominal flow of a 1.7 m³/s air handling unit; a convention, so priors read alike across coils).
REFERENCE_AIR_MASS_FLOW = 2.0
#: Floor of flow ratios and capacity rates: a stagnant side conducts (almost) nothing.
TINY = 1e-9
#: Cap of the capacity ratio C_r (:func:`counterflow_effectiveness`).
_RATIO_CAP = 1.0 - 1e-7


@njit(cache=True)
def effectiveness_scalar(ntu: float, capacity_ratio: float) -> float:
    """ε of a counter-flow heat exchanger [1] (Incropera & DeWitt, Table 11.3)::

        ε = (1 − e^{−NTU(1−C_r)}) / (1 − C_r·e^{−NTU(1−C_r)})

    C_r is capped at 1 − 10⁻⁷, where the formula meets the balanced limit NTU/(1 + NTU) within
    10⁻⁶; C_r = 0 gives 1 − e^{−NTU}.
    """
    ratio = np.minimum(capacity_ratio, _RATIO_CAP)
    decay = np.exp(ntu * (ratio - 1.0))  # e^{−NTU(1−C_r)}
    return (1.0 - decay) / (1.0 - ratio * decay)


@njit(cache=True)
def film_ua_scalar(water_conductance_w_per_k: float, water_flow_ratio: float, air_conductance_w_per_k: float,
                   air_flow_ratio: float) -> float:
    """UA [W/K] of the two film conductances in series (module docstring): hA at the reference flows
    and the flow ratios ṁ/ṁ_ref [1]; a ratio of 0 (no flow on that side) gives UA ≈ 0."""
    water = water_conductance_w_per_k * np.maximum(water_flow_ratio, TINY) ** FILM_EXPONENT
    air = air_conductance_w_per_k * np.maximum(air_flow_ratio, TINY) ** FILM_EXPONENT
    return water * air / (water + air)


@njit(cache=True)
def heat_rate_scalar(ua_w_per_k: float, water_capacity_w_per_k: float, air_capacity_w_per_k: float,
                     water_inlet_temperature: float, air_inlet_temperature: float) -> float:
    """Q = ε·C_min·(T_w,in − T_a,in) [W], positive when the water heats the air; capacity rates of 0
    floored at 10⁻⁹ W/K, so a side without flow transfers no heat instead of dividing by zero."""
    c_water = np.maximum(water_capacity_w_per_k, TINY)
    c_air = np.maximum(air_capacity_w_per_k, TINY)
    c_min = np.minimum(c_water, c_air)
    c_max = np.maximum(c_water, c_air)
    return (effectiveness_scalar(ua_w_per_k / c_min, c_min / c_max) * c_min
            * (water_inlet_temperature - air_inlet_temperature))


#: :func:`effectiveness_scalar` over arrays (a numpy ufunc: broadcasts).
counterflow_effectiveness = vectorize(["float64(float64, float64)"], cache=True)(effectiveness_scalar)
_film_ua = vectorize(["float64(float64, float64, float64, float64)"], cache=True)(film_ua_scalar)
_heat_rate = vectorize(["float64(float64, float64, float64, float64, float64)"], cache=True)(heat_rate_scalar)


def series_film_ua_w_per_k(
    *, water_conductance_w_per_k: np.ndarray, water_flow_ratio: np.ndarray,
    air_conductance_w_per_k: np.ndarray, air_flow_ratio: np.ndarray,
) -> np.ndarray:
    """:func:`film_ua_scalar` over arrays."""
    return _film_ua(water_conductance_w_per_k, water_flow_ratio, air_conductance_w_per_k, air_flow_ratio)


def coil_heat_rate_w(
    ua_w_per_k: np.ndarray, *, water_capacity_w_per_k: np.ndarray, air_capacity_w_per_k: np.ndarray,
    water_inlet_temperature: np.ndarray, air_inlet_temperature: np.ndarray,
) -> np.ndarray:
    """:func:`heat_rate_scalar` over arrays."""
    return _heat_rate(ua_w_per_k, water_capacity_w_per_k, air_capacity_w_per_k, water_inlet_temperature,
                      air_inlet_temperature)
