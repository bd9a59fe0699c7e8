"""PI controller, output limited to 0–1, back-calculation anti-windup: reverse acting (a heating
valve) or direct acting (a cooling valve)."""

from __future__ import annotations

import numpy as np
from numba import njit

from service.components.compiled import as_row, member_value
from service.components.component import ComponentModel, Parameter, Port

__all__ = ["PIController", "DirectActingPIController"]


@njit(cache=True)
def _pi_step(setpoint, measured, gain, integral_time, integral, action: float, dt_s: float):
    """One step of every member (:class:`PIController`'s equations), its integral [n] updated in
    place; the inputs and parameters [n] or [1]. Returns the control signal u [n]."""
    signal = np.empty(integral.shape[0])
    for m in range(integral.shape[0]):
        w, y = member_value(setpoint, m), member_value(measured, m)
        k_p, t_i = member_value(gain, m), member_value(integral_time, m)
        error = w - y if action > 0.0 else y - w  # a·(w − y), a = ±1
        unlimited = k_p * (error + integral[m] / t_i)
        u = np.minimum(np.maximum(unlimited, 0.0), 1.0)
        integral[m] += dt_s * (error + (u - unlimited) * t_i / (k_p * np.maximum(t_i, dt_s)))
        signal[m] = u
    return signal


class PIController(ComponentModel):
    """u = clip(v, 0, 1),  v = K_p · (e + I / T_i),  e = a · (w − y)   [1]

    I ← I + Δt · (e + (u − v) · T_i / (K_p · T_t)),  T_t = max(T_i, Δt)   [K·s]

    Reverse acting, a = +1 (heating: the output rises while the measured value y is below the
    setpoint w); :class:`DirectActingPIController` has a = −1. Back-calculation anti-windup (Åström
    & Hägglund): while saturated, (u − v) pulls K_p·I/T_i back to the limit with tracking time T_t,
    so the controller leaves the limit as soon as the error changes sign. Sampled at the simulation
    step, with the loop's *effective* gains there; starts with I = 0. Why back-calculation, the
    gains' priors and the warm-up: ``docs/components.md``.
    """

    inputs = (
        Port("setpoint", "degC", "setpoint, w"),
        Port("measured_value", "degC", "controlled value, y", feedback=True),
    )
    outputs = (Port("control_signal", "1", "control signal, u (0–1)"),)
    parameters = (
        Parameter("proportional_gain", "1/K", 0.015, 0.003, 0.04, "proportional gain, K_p"),
        Parameter("integral_time", "s", 1200.0, 600.0, 3600.0, "integral time, T_i"),
    )
    states = ("integral",)
    #: A day: a low-gain loop takes hours to build its integral from zero (``docs/components.md``).
    settling_s = 86400.0
    #: Six hours: the integral a warm-up builds on a repeated first day is not the plant's, and the
    #: loop carries the difference for hours (``docs/components.md``, *Start memory*).
    start_memory_s = 6 * 3600.0
    #: a in the error e = a · (w − y): +1 reverse acting, −1 direct acting (no other value)
    action = 1.0

    def initial_state(self, params, inputs, dt_s):
        return {"integral": np.zeros(np.broadcast(inputs["setpoint"], inputs["measured_value"],
                                                  params["proportional_gain"], params["integral_time"]).shape)}

    def step(self, params, inputs, state, dt_s):
        rows = [as_row(values) for values in (
            inputs["setpoint"], inputs["measured_value"], params["proportional_gain"], params["integral_time"])]
        return {"control_signal": _pi_step(*rows, state["integral"], self.action, float(dt_s))}


class DirectActingPIController(PIController):
    """:class:`PIController` acting directly (a = −1): the output rises while the measured value is
    above the setpoint, as a chilled-water valve opens when the supply air is too warm."""

    action = -1.0
