"""A first-order lag: a sensor's response time, or the thermal mass of a coil modelled as static."""

from __future__ import annotations

import numpy as np

from service.components.component import Parameter, Port, SplicedEffect, first_order_lag_factor

__all__ = ["FirstOrderLag", "SensorResponseLag"]


class FirstOrderLag(SplicedEffect):
    """τ · dy/dt = x − y, discretised exactly: y_k = y_{k−1} + (1 − e^{−Δt/τ}) · (x_k − y_{k−1}).

    The output at step k already includes x_k, so τ = 0 (the null value) passes x through
    unchanged. Starts in steady state (y_{−1} = x_0). τ in s.
    """

    inputs = (Port("value_in", "degC", "value before the lag"),)
    outputs = (Port("value_out", "degC", "lagged value"),)
    parameters = (Parameter("time_constant", "s", 0.0, 0.0, 1800.0, "first-order time constant, τ", null=0.0),)
    states = ("lagged",)

    @classmethod
    def settling_time_s(cls) -> float:
        """Five time constants at the slowest its prior allows (a subclass's own prior included)."""
        return 5.0 * cls.parameters[0].upper

    def initial_state(self, params, inputs, dt_s):
        return {"lagged": inputs["value_in"].copy()}

    def step(self, params, inputs, state, dt_s):
        tau = params["time_constant"]
        if state.get("_time_constant") is not tau:  # the factor kept while the same τ comes
            factor = first_order_lag_factor(dt_s, tau)
            closed = factor == 1.0
            state["_time_constant"], state["_factor"], state["_closed"] = tau, factor, closed if closed.any() else None
        lagged = state["lagged"]
        lagged += state["_factor"] * (inputs["value_in"] - lagged)
        if state["_closed"] is not None:  # no lag (τ = 0, the null): x itself, to the last bit (y + (x − y)
            # rounds where x and y differ in magnitude; the diagnosis's shared model holds the effect at its null)
            np.copyto(lagged, inputs["value_in"], where=state["_closed"])
        return {"value_out": lagged.copy()}


class SensorResponseLag(FirstOrderLag):
    """:class:`FirstOrderLag` with τ up to 2 h [s]: a water sensor that has lost its contact with the
    water (a strap-on sensor off its pipe, a thermowell without its paste) answers in tens of minutes
    to hours; in contact, or in moving air, within minutes (:class:`FirstOrderLag`'s 30 min)."""

    parameters = (Parameter("time_constant", "s", 0.0, 0.0, 7200.0, "sensor time constant, τ", null=0.0),)
