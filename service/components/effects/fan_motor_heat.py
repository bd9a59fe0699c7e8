"""Fan motor and drive losses carried into the air stream."""

from __future__ import annotations

from service.components.component import Parameter, Port, SplicedEffect
from service.components.fan import IMPELLER_HEAT_SHARE, fan_heat_rise_k

__all__ = ["FanMotorHeat"]


class FanMotorHeat(SplicedEffect):
    """T_out = T_in + f_m · P / (ṁ · c_p)   [°C]  (:func:`~service.components.fan.fan_heat_rise_k`)

    P the fan's electric power (W), ṁ the air mass flow (kg/s), f_m the share of the power that the
    motor and its drive lose into the air stream when they sit in it, on top of the impeller's
    losses the base fan already puts there (0.3 of P): at most 0.7, so the air gets no more than P.
    Null: f_m = 0.
    """

    inputs = (
        Port("value_in", "degC", "air temperature leaving the fan, its impeller's losses included"),
        Port("electric_power", "W", "fan electric power"),
        Port("air_mass_flow", "kg/s", "air mass flow through the fan"),
    )
    outputs = (Port("value_out", "degC", "air temperature leaving the fan"),)
    parameters = (
        Parameter("motor_heat_fraction", "1", 0.0, 0.0, 1.0 - IMPELLER_HEAT_SHARE,
                  "share of fan power the motor and drive lose into the air, f_m", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        rise = fan_heat_rise_k(params["motor_heat_fraction"], inputs["electric_power"], inputs["air_mass_flow"])
        return {"value_out": inputs["value_in"] + rise}
