"""A constant sensor bias."""

from __future__ import annotations

from service.components.component import Parameter, Port, SplicedEffect

__all__ = ["SensorOffset"]


class SensorOffset(SplicedEffect):
    """y = x + b   [°C]: the sensor reads b above the true value. Null: b = 0."""

    inputs = (Port("value_in", "degC", "true value at the sensor"),)
    outputs = (Port("value_out", "degC", "value the sensor reports"),)
    parameters = (Parameter("offset", "K", 0.0, -5.0, 5.0, "sensor bias, b", null=0.0),)

    def step(self, params, inputs, state, dt_s):
        return {"value_out": inputs["value_in"] + params["offset"]}
