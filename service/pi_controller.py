"""PI controller, reverse acting, output limited to 0–1, conditional-integration anti-windup."""

from __future__ import annotations

import numpy as np

from .component import ComponentModel, Parameter, Port

__all__ = ["PIController"]


class PIController(ComponentModel):
    """u = clip(K_p · (e + I / T_i), 0, 1),  e = w − y   [1]

    Reverse acting (heating: the output rises while the measured value y is below the setpoint w).
    The integral I [K·s] advances by e·Δt each step **unless** the output is saturated and the error
    would drive it further into saturation (conditional integration): after a long saturation the
    controller leaves the limit as soon as the error changes sign, without unwinding a huge integral.
    Sampled at the simulation step. Starts with I such that u equals its proportional part (I = 0).
    Bounds: K_p 0.005–0.5 /K (0.5–50 % valve per K), T_i 60–1800 s: the range of commissioned
    supply-air loops; wider priors make the discrete loop oscillate without physical meaning.
    """

    inputs = (
        Port("setpoint", "degC", "setpoint, w"),
        Port("measured_value", "degC", "controlled value, y", feedback=True),
    )
    outputs = (Port("control_signal", "1", "control signal, u (0–1)"),)
    parameters = (
        Parameter("proportional_gain", "1/K", 0.05, 0.005, 0.5, "proportional gain, K_p"),
        Parameter("integral_time", "s", 300.0, 60.0, 1800.0, "integral time, T_i"),
    )
    states = ("integral",)

    def initial_state(self, params, inputs, dt_s):
        return {"integral": np.zeros_like(np.asarray(inputs["setpoint"], dtype=float) + params["proportional_gain"])}

    def step(self, params, inputs, state, dt_s):
        error = inputs["setpoint"] - inputs["measured_value"]
        gain, integral = params["proportional_gain"], state["integral"]
        raw = gain * (error + integral / params["integral_time"])
        signal = np.clip(raw, 0.0, 1.0)
        winding = ((raw >= 1.0) & (error > 0.0)) | ((raw <= 0.0) & (error < 0.0))
        integral += np.where(winding, 0.0, error * dt_s)
        return {"control_signal": signal}
