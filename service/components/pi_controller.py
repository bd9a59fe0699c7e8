"""PI controller, output limited to 0–1, back-calculation anti-windup: reverse acting (a heating
valve) or direct acting (a cooling valve)."""

from __future__ import annotations

import numpy as np

from service.components.component import ComponentModel, Parameter, Port

__all__ = ["PIController", "DirectActingPIController"]


class PIController(ComponentModel):
    """u = clip(v, 0, 1),  v = K_p · (e + I / T_i),  e = a · (w − y)   [1]

    I ← I + Δt · (e + (u − v) · T_i / (K_p · T_t)),  T_t = max(T_i, Δt)   [K·s]

    Reverse acting, a = +1 (heating: the output rises while the measured value y is below the
    setpoint w); :class:`DirectActingPIController` has a = −1 (cooling: it rises while y is above w).
    Back-calculation anti-windup (Åström & Hägglund): while the output is unsaturated u = v and the
    integral I [K·s] advances by e·Δt; while it is saturated the term (u − v) pulls the integral
    part K_p·I/T_i back to the limit with the tracking time T_t, so after a long saturation the
    controller leaves the limit as soon as the error changes sign (at a fixed point at the limit,
    K_p·I/T_i equals the limit exactly), without unwinding a huge integral. T_t ≥ Δt keeps the
    sampled tracking from overshooting. Unlike conditional integration, which switches the integral's
    increment on or off by whether v is past a limit, the simulated trajectory is a continuous function
    of the gains: with that switch the calibration cost along a line to the truth was a sawtooth
    (0.3–2.8, jumps where one step's increment flipped) that stopped the point fit in a false minimum.
    Sampled at the simulation step. Starts with I such that u equals its proportional part (I = 0);
    a simulated window starts after a day's warm-up (:attr:`settling_s`): a low-gain loop takes
    hours to build the integral a running unit has.
    The gains are the *effective* gains of the loop sampled at the simulation step (minutes, where a
    BMS samples every second): K_p 0.005–0.05 /K (0.5–5 % valve per K) and T_i 600–3600 s keep the
    discrete loop of a hot-water coil stable across the prior box at a 5-minute step (checked over
    random draws of the other parameters); wider priors make the simulated loop oscillate, a limit
    cycle no measurement shows.
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
    #: A day: a low-gain loop (K_p 0.012 /K, T_i 1,850 s) takes ~5 h to build its integral from zero
    #: and as long to wind down after a night setback; at the priors' slow corner longer still.
    settling_s = 86400.0
    #: Six hours: the integral a warm-up builds on the data's first day repeated is not the one the
    #: plant had (its day before differed), and at typical gains the loop carries the difference for
    #: hours. Over 30 synthetic truths (seeds 9–38 of the case study, 2026-11-26) the point fits'
    #: offsets from the truth were 2.1 standard errors (root mean square) scoring the first day after
    #: one hour, 1.3 after six hours, and 1.3 on the second day, whose warm-up is the measured first:
    #: six hours leave no more of the start state than a measured history does.
    start_memory_s = 6 * 3600.0
    #: a in the error e = a · (w − y): +1 reverse acting, −1 direct acting
    action = 1.0

    def initial_state(self, params, inputs, dt_s):
        return {"integral": np.zeros_like(np.asarray(inputs["setpoint"], dtype=float) + params["proportional_gain"])}

    def step(self, params, inputs, state, dt_s):
        error = self.action * (inputs["setpoint"] - inputs["measured_value"])
        gain, integral_time, integral = params["proportional_gain"], params["integral_time"], state["integral"]
        unlimited = gain * (error + integral / integral_time)
        signal = np.minimum(np.maximum(unlimited, 0.0), 1.0)
        tracking_s = np.maximum(integral_time, dt_s)
        integral += dt_s * (error + (signal - unlimited) * integral_time / (gain * tracking_s))
        return {"control_signal": signal}


class DirectActingPIController(PIController):
    """:class:`PIController` acting directly (a = −1): the output rises while the measured value is
    above the setpoint, as a chilled-water valve opens when the supply air is too warm."""

    action = -1.0
