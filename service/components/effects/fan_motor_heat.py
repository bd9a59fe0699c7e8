"""Fan motor and drive losses carried into the air stream."""

from __future__ import annotations

from service.components.component import Parameter, Port, SplicedEffect
from service.components.fan import fan_heat_rise_k

__all__ = ["FanMotorHeat"]


class FanMotorHeat(SplicedEffect):
    """T_out = T_in + f_m · P / (ṁ · c_p)   [°C]  (:func:`~service.components.fan.fan_heat_rise_k`)

    P the fan's electric power (W), ṁ the air mass flow (kg/s), f_m the share of the power heating
    the air beyond what the base fan puts there: a motor and drive in the air stream lose theirs
    into it (ASHRAE Handbook Fundamentals ch. 18). The base fan counts its impeller's losses (0.3 of
    P) where a meter measures P, nothing where none does; f_m is then all of the fan's heat. Null: f_m = 0.
    """

    inputs = (
        Port("value_in", "degC", "air temperature leaving the fan without motor heat"),
        Port("electric_power", "W", "fan electric power"),
        Port("air_mass_flow", "kg/s", "air mass flow through the fan"),
    )
    outputs = (Port("value_out", "degC", "air temperature leaving the fan"),)
    parameters = (
        Parameter("motor_heat_fraction", "1", 0.0, 0.0, 1.0,
                  "share of fan power heating the air beyond the base fan's, f_m", null=0.0),
    )

    share_of_host_parameters = ("nominal_power",)

    def step(self, params, inputs, state, dt_s):
        rise = fan_heat_rise_k(params["motor_heat_fraction"], inputs["electric_power"], inputs["air_mass_flow"])
        return {"value_out": inputs["value_in"] + rise}
