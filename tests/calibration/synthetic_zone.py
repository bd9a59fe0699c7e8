"""Synthetic calibration problems: a heated zone with a proportional controller, vectorised.

Zone air temperature T (°C), first order with the exact discretisation of the component contract::

    T_{k+1} = T_k + (1 − exp(−Δt · UA / C)) · (T∞,k − T_k),   T∞,k = T_out,k + (η P u_k + G_k) / UA
    u_k     = clip(K_p (T_set,k − T_k), 0, 1)            (the heater signal, a second target)

Parameters: UA (W/K), C (J/K), heater efficiency η (1), heater power P (W). η and P enter only as the
product η·P: one unidentifiable combination. The outdoor temperature is a daily sinusoid plus a
seeded AR(1) wander; the setpoint steps between 16 °C (night) and 21 °C (06–22 h); internal gains
300 W during 08–18 h. Observations = truth + white noise (σ = 0.1 K and 0.01), optionally + a slow
sinusoidal disturbance on the temperature that the model lacks.
"""

from __future__ import annotations

import numpy as np

from service.calibration.problem import CalibrationProblem

DAY_S = 86400.0
NAMES = ("UA_W_per_K", "C_J_per_K", "heater_efficiency", "heater_power_W")
LOWER = np.array([50.0, 5e5, 0.5, 500.0])
UPPER = np.array([500.0, 2e7, 1.0, 8000.0])
TRUTH = np.array([200.0, 4e6, 0.8, 5000.0])
CONTROLLER_GAIN_PER_K = 0.8


def simulate_zone(theta, outdoor, setpoint, gains, initial_temperature, dt_s):
    """``theta ndarray[n_ens, 4]`` → ``{"zone_temperature", "heater_signal": ndarray[n_ens, n_t]}``."""
    ua, capacity, efficiency, power = np.asarray(theta, dtype=float).T
    lag = -np.expm1(-dt_s * ua / capacity)
    heat_per_signal = efficiency * power
    n_t = outdoor.size
    temperature = np.full(ua.shape, float(initial_temperature))
    zone = np.empty((ua.size, n_t))
    signal = np.empty((ua.size, n_t))
    for k in range(n_t):
        u = np.clip(CONTROLLER_GAIN_PER_K * (setpoint[k] - temperature), 0.0, 1.0)
        zone[:, k] = temperature
        signal[:, k] = u
        equilibrium = outdoor[k] + (heat_per_signal * u + gains[k]) / ua
        temperature = temperature + lag * (equilibrium - temperature)
    return {"zone_temperature": zone, "heater_signal": signal}


def zone_windows(
    n_windows: int = 1,
    steps_per_day: int = 144,
    seed: int = 0,
    estimate: tuple[str, ...] = NAMES,
    targets: tuple[str, ...] = ("zone_temperature", "heater_signal"),
    disturbance_k: float = 0.0,
    disturbance_period_s: float = DAY_S,
    time_of_day_input: bool = False,
) -> list[CalibrationProblem]:
    """Consecutive one-day windows (after a one-day warm-up) of the synthetic zone.

    Parameters not in ``estimate`` are fixed at the truth. ``time_of_day_input`` gives the problems
    the time of day (fraction of a day) as their GP input.
    """
    rng = np.random.default_rng(seed)
    dt_s = DAY_S / steps_per_day
    n_total = (n_windows + 1) * steps_per_day
    t = np.arange(n_total) * dt_s
    hour = (t % DAY_S) / 3600.0
    wander = np.cumsum(rng.normal(0.0, 0.15, n_total))
    outdoor = 5.0 + 4.0 * np.sin(2 * np.pi * (hour - 9.0) / 24.0) + wander - wander.mean()
    setpoint = np.where((hour >= 6.0) & (hour < 22.0), 21.0, 14.0)
    gains = np.where((hour >= 8.0) & (hour < 18.0), 1500.0, 0.0)
    truth = simulate_zone(TRUTH[None, :], outdoor, setpoint, gains, 18.0, dt_s)
    columns = [NAMES.index(name) for name in estimate]
    noise = {"zone_temperature": 0.1, "heater_signal": 0.01}
    units = {"zone_temperature": "degC", "heater_signal": "1"}
    problems = []
    for w in range(1, n_windows + 1):
        window = slice(w * steps_per_day, (w + 1) * steps_per_day)
        start_temperature = truth["zone_temperature"][0, window.start]
        boundary = (outdoor[window], setpoint[window], gains[window])

        def simulate(theta, boundary=boundary, start_temperature=start_temperature):
            full = np.repeat(TRUTH[None, :], theta.shape[0], axis=0)
            full[:, columns] = theta
            outputs = simulate_zone(full, *boundary, start_temperature, dt_s)
            return {key: outputs[key] for key in targets}

        observed = {}
        for key in targets:
            values = truth[key][0, window] + rng.normal(0.0, noise[key], steps_per_day)
            if key == "zone_temperature" and disturbance_k:
                values = values + disturbance_k * np.sin(2 * np.pi * t[window] / disturbance_period_s)
            observed[key] = values
        problems.append(
            CalibrationProblem(
                parameter_names=tuple(estimate),
                lower=LOWER[columns],
                upper=UPPER[columns],
                simulate=simulate,
                observed=observed,
                units={key: units[key] for key in targets},
                gp_inputs=(hour[window] / 24.0)[:, None] if time_of_day_input else None,
            )
        )
    return problems
