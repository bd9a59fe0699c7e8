"""Mixing box of an air handling unit: outdoor and return air mixed by the damper position."""

from __future__ import annotations

import numpy as np

from .component import ComponentModel, Parameter, Port

__all__ = ["MixingBox"]


class MixingBox(ComponentModel):
    """T_mix = x·T_oa + (1 − x)·T_ra,   x = x_min + (x_max − x_min)·d^γ   [°C]

    d the outdoor-air damper command (0–1, clipped), x the outdoor-air fraction: x_min the fraction
    with the damper shut (leakage, minimum-air path), x_max with it fully open (the return damper
    never seals completely), γ the damper's installed characteristic (1 linear; < 1 opening fast,
    as parallel-blade dampers with low authority do). Static: the box has no storage.
    """

    inputs = (
        Port("outdoor_air_temperature", "degC", "outdoor air temperature"),
        Port("return_air_temperature", "degC", "return air temperature"),
        Port("outdoor_damper_position", "1", "outdoor air damper command, d"),
    )
    outputs = (
        Port("mixed_air_temperature", "degC", "mixed air temperature"),
        Port("outdoor_air_fraction", "1", "outdoor air fraction, x"),
    )
    parameters = (
        Parameter("minimum_outdoor_air_fraction", "1", 0.05, 0.0, 0.4, "outdoor air fraction with the damper shut, x_min"),
        Parameter("maximum_outdoor_air_fraction", "1", 0.9, 0.5, 1.0, "outdoor air fraction with the damper open, x_max"),
        Parameter("damper_exponent", "1", 1.0, 0.3, 3.0, "installed damper characteristic, γ"),
    )

    def step(self, params, inputs, state, dt_s):
        opening = np.minimum(np.maximum(inputs["outdoor_damper_position"], 0.0), 1.0)
        low, high = params["minimum_outdoor_air_fraction"], params["maximum_outdoor_air_fraction"]
        fraction = low + (high - low) * opening ** params["damper_exponent"]
        outdoor, ret = inputs["outdoor_air_temperature"], inputs["return_air_temperature"]
        return {"mixed_air_temperature": ret + fraction * (outdoor - ret), "outdoor_air_fraction": fraction}
