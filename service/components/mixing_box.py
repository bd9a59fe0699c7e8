"""Mixing box of an air handling unit: outdoor and return air mixed by the outdoor-air damper."""

from __future__ import annotations

import numpy as np

from service.components.component import ComponentModel, Parameter, Port

__all__ = ["MixingBox"]


class MixingBox(ComponentModel):
    """T_mix = T_ra + x·(T_oa − T_ra),   x = x_min + (x_max − x_min)·d^γ   [°C, 1]

    Adiabatic mixing of two dry-air streams, x = ṁ_oa/ṁ_supply the outdoor-air fraction, d the
    outdoor-air damper command (0–1, clipped; the return damper moves opposite to it). x_min: the
    fraction with the damper shut, x_max: fully open, γ: the installed damper characteristic (1
    linear, < 1 quick-opening, > 1 slow-opening). Static: the plenum is mixed within seconds.
    """

    inputs = (
        Port("outdoor_air_temperature", "degC", "outdoor air temperature, T_oa"),
        Port("return_air_temperature", "degC", "return air temperature, T_ra"),
        Port("outdoor_damper_position", "1", "outdoor-air damper command, d"),
    )
    outputs = (
        Port("mixed_air_temperature", "degC", "mixed air temperature, T_mix"),
        Port("outdoor_air_fraction", "1", "outdoor-air fraction of the supply air, x"),
    )
    parameters = (
        Parameter("minimum_outdoor_air_fraction", "1", 0.05, 0.0, 0.4, "outdoor-air fraction with the damper shut, x_min"),
        Parameter("maximum_outdoor_air_fraction", "1", 0.9, 0.5, 1.0, "outdoor-air fraction with the damper open, x_max"),
        Parameter("damper_exponent", "1", 1.0, 0.3, 3.0, "installed damper characteristic, γ"),
    )

    def step(self, params, inputs, state, dt_s):
        opening = np.minimum(np.maximum(inputs["outdoor_damper_position"], 0.0), 1.0)
        low = params["minimum_outdoor_air_fraction"]
        fraction = low + (params["maximum_outdoor_air_fraction"] - low) * opening ** params["damper_exponent"]
        ret = inputs["return_air_temperature"]
        return {
            "mixed_air_temperature": ret + fraction * (inputs["outdoor_air_temperature"] - ret),
            "outdoor_air_fraction": fraction,
        }
