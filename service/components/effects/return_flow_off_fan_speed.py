"""Recirculated air that does not follow the supply fan's speed (a return fan at its own speed)."""

from __future__ import annotations

import numpy as np

from service.components.component import Parameter, Port, SplicedEffect

__all__ = ["ReturnFlowOffFanSpeed", "MINIMUM_FAN_SPEED"]

#: Fan speed (share of full speed) below which the effect holds the speed there: the recirculated
#: share of a fan at a standstill is undefined (no air moves; the mixed air is then clipped).
MINIMUM_FAN_SPEED = 0.05


class ReturnFlowOffFanSpeed(SplicedEffect):
    """T_mix' = T_oa − (T_oa − T_mix) · s^(−β),  clipped to [min(T_oa, T_ra), max(T_oa, T_ra)]   [°C]

    The recirculated flow ∝ s^(1−β) while the supply flow ∝ s (s the supply fan speed, 0–1, at least
    :data:`MINIMUM_FAN_SPEED`), so the outdoor-air share grows with the fan's speed: β = 1 a
    recirculated flow fixed whatever the supply fan does, β = 0 (null) both scale with the fan (the
    base model). The derivation: ``docs/components.md``.
    """

    inputs = (
        Port("value_in", "degC", "mixed air temperature with both streams following the fan, T_mix"),
        Port("outdoor_air_temperature", "degC", "outdoor air temperature, T_oa"),
        Port("return_air_temperature", "degC", "return air temperature, T_ra"),
        Port("fan_speed", "1", "supply fan speed command, s"),
    )
    outputs = (Port("value_out", "degC", "mixed air temperature, T_mix'"),)
    parameters = (
        Parameter("recirculation_speed_exponent", "1", 0.0, 0.0, 2.0,
                  "how far the recirculated flow fails to follow the supply fan's speed, β", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        outdoor, ret = inputs["outdoor_air_temperature"], inputs["return_air_temperature"]
        speed = np.maximum(inputs["fan_speed"], MINIMUM_FAN_SPEED)
        value_in, beta = inputs["value_in"], params["recirculation_speed_exponent"]
        mixed = outdoor - (outdoor - value_in) * speed ** -beta
        # at the null T_mix itself, to the last bit: T_oa − (T_oa − T_mix) rounds, and the clip may move
        # a mixing box's T_mix that lies an ulp outside; the diagnosis's shared model holds the effect
        # at its null for every other candidate (service/diagnosis/shared_runs.py)
        return {"value_out": np.where(beta == 0.0, value_in,
                                      np.clip(mixed, np.minimum(outdoor, ret), np.maximum(outdoor, ret)))}
