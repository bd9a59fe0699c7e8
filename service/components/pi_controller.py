"""PI controller, output limited to 0–1, back-calculation anti-windup: reverse acting (a heating
valve) or direct acting (a cooling valve)."""

from __future__ import annotations

import numpy as np

from service.components.component import ComponentModel, Parameter, Port

__all__ = ["PIController", "DirectActingPIController"]

# 0-d arrays: numpy's ufuncs take them faster than Python floats
_ZERO, _ONE = np.array(0.0), np.array(1.0)


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
        return {"integral": np.zeros_like(np.asarray(inputs["setpoint"], dtype=float) + params["proportional_gain"])}

    def step(self, params, inputs, state, dt_s):
        setpoint, measured = inputs["setpoint"], inputs["measured_value"]
        error = setpoint - measured if self.action > 0.0 else measured - setpoint  # a·(w − y), a = ±1
        gain, integral_time, integral = params["proportional_gain"], params["integral_time"], state["integral"]
        unlimited = gain * (error + integral / integral_time)
        signal = np.minimum(np.maximum(unlimited, _ZERO), _ONE)
        tracking_s = np.maximum(integral_time, dt_s)
        integral += dt_s * (error + (signal - unlimited) * integral_time / (gain * tracking_s))
        return {"control_signal": signal}


class DirectActingPIController(PIController):
    """:class:`PIController` acting directly (a = −1): the output rises while the measured value is
    above the setpoint, as a chilled-water valve opens when the supply air is too warm."""

    action = -1.0
