"""Measuring devices, schedules and logged commands: the model's interface to measured data."""

from __future__ import annotations

from service.components.component import ComponentModel, Port

__all__ = ["MeasuringDevice"]


class MeasuringDevice(ComponentModel):
    """y = x: the value at the device.

    One model for sensors, meters, setpoint schedules and logged commands; their signature files
    differ by what they observe. A *boundary* device (no connected input, the paper's Eq. 1) gets
    its measured series through ``measured_value`` and replays it; a *target* device (one connected
    input) passes the modelled value through: the virtual sensor compared with the measurement.
    Units are the quantity's simulator unit (°C, m³/s, W, 1).
    """

    inputs = (Port("measured_value", "", "the value at the device: measured (boundary) or modelled (target)"),)
    outputs = (Port("measured_value", "", "the value the device reports"),)

    def step(self, params, inputs, state, dt_s):
        return {"measured_value": inputs["measured_value"]}
