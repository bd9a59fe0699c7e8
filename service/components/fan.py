"""Fan with a measured air flow: polynomial part-load power curve (the paper's Sec. 5.1, Table 2)."""

from __future__ import annotations

import numpy as np

from service.components.component import (
    AIR_DENSITY_KG_PER_M3,
    AIR_SPECIFIC_HEAT_J_PER_KG_K,
    MINIMUM_AIR_MASS_FLOW_KG_PER_S,
    ComponentModel,
    Parameter,
    Port,
)

__all__ = ["IMPELLER_HEAT_SHARE", "Fan", "fan_heat_rise_k", "part_load_power_fraction"]

#: Share of a fan's electric power that heats the air at the fan with its motor outside the air
#: stream: the impeller's losses, (1 − η_fan)·η_motor·η_drive = 0.30 for η_fan = 0.65 and
#: η_motor·η_drive = 0.87 (the fan's useful work is dissipated downstream, in the duct system).
IMPELLER_HEAT_SHARE = 0.3


def fan_heat_rise_k(share: np.ndarray, power_w: np.ndarray, air_mass_flow_kg_per_s: np.ndarray) -> np.ndarray:
    """ΔT = share·P/(max(ṁ, ṁ_min)·c_p) [K]: the rise of the air temperature across a fan that puts
    ``share`` of its electric power P [W] into an air stream of ṁ [kg/s] (ṁ_min:
    ``MINIMUM_AIR_MASS_FLOW_KG_PER_S``)."""
    flow = np.maximum(air_mass_flow_kg_per_s, MINIMUM_AIR_MASS_FLOW_KG_PER_S)
    return share * power_w / (flow * AIR_SPECIFIC_HEAT_J_PER_KG_K)


def part_load_power_fraction(flow_fraction: np.ndarray, *, c1: np.ndarray, c2: np.ndarray, c3: np.ndarray,
                             c4: np.ndarray) -> np.ndarray:
    """c1 + c2·f + c3·f² + c4·f³ (Horner), clipped at 0, and 0 where f ≤ 0 (the fan is off: c1 is the
    curve's constant term while it runs, not a stand-by draw) [1]."""
    fraction = np.maximum(c1 + flow_fraction * (c2 + flow_fraction * (c3 + flow_fraction * c4)), 0.0)
    return np.where(flow_fraction > 0.0, fraction, 0.0)


class Fan(ComponentModel):
    """P = P_nom · (c1 + c2·f + c3·f² + c4·f³),  f = max(V̇, 0) / V̇_nom   [W];  P = 0 at f = 0 (off)

    ṁ = ρ_air · V̇ [kg/s] with ρ_air = 1.204 kg/m³;  T_out = T_in + f_imp·P/(ṁ·c_p) (``fan_heat_rise_k``):
    the impeller's losses heat the air, f_imp = 0.3 where a meter measures the fan's power and 0
    where none does (fixed, not estimated; a motor in the air stream adds its own losses, the
    FanMotorHeat effect). Defaults: the ASHRAE 90.1 Appendix G variable-speed fan curve (c1..c4 =
    0.0013, 0.1470, 0.9506, −0.0998, sum 0.9991 at f = 1); bounds wide enough for inlet-vane,
    variable-pitch and EC fans.
    """

    inputs = (
        Port("air_volume_flow", "m3/s", "air volume flow through the fan, V̇"),
        Port("inlet_air_temperature", "degC", "air temperature at the fan inlet"),
    )
    outputs = (
        Port("outlet_air_temperature", "degC", "air temperature at the fan outlet"),
        Port("outlet_air_mass_flow", "kg/s", "air mass flow, ṁ"),
        Port("electric_power", "W", "electric power drawn, P"),
    )
    parameters = (
        Parameter("nominal_air_flow", "m3/s", 1.5, 0.1, 20.0, "nominal air volume flow, V̇_nom"),
        Parameter("nominal_power", "W", 1800.0, 50.0, 50000.0, "electric power at nominal flow, P_nom"),
        Parameter("c1", "1", 0.0013, 0.0, 0.3, "part-load curve, constant term"),
        Parameter("c2", "1", 0.1470, -0.5, 1.0, "part-load curve, linear term"),
        Parameter("c3", "1", 0.9506, -1.0, 2.0, "part-load curve, quadratic term"),
        Parameter("c4", "1", -0.0998, -1.0, 1.5, "part-load curve, cubic term"),
        Parameter("impeller_heat_share", "1", IMPELLER_HEAT_SHARE, 0.0, 1.0,
                  "share of the electric power the impeller's losses put into the air, f_imp"),
    )

    #: What only the electric power depends on: fixed at their defaults where no meter measures it.
    power_curve_parameters = ("nominal_air_flow", "nominal_power", "c1", "c2", "c3", "c4")

    @classmethod
    def parameters_fixed_by_measurement(cls, measured_outputs: frozenset[str]) -> dict[str, float]:
        """f_imp = ``IMPELLER_HEAT_SHARE`` where a meter measures the fan's electric power. Where none
        does, f_imp = 0 and the power curve (:attr:`power_curve_parameters`) at its defaults (the
        graph's nominal values win): no data pin it, and a fitted curve would make the heat of a motor
        in the air stream (FanMotorHeat, f_m·P) a heat source of any shape of the flow
        (``docs/components.md``)."""
        if "electric_power" in measured_outputs:
            return {"impeller_heat_share": IMPELLER_HEAT_SHARE}
        defaults = {p.name: p.default for p in cls.parameters if p.name in cls.power_curve_parameters}
        return {"impeller_heat_share": 0.0, **defaults}

    def step(self, params, inputs, state, dt_s):
        flow = np.maximum(inputs["air_volume_flow"], 0.0)
        fraction = flow / params["nominal_air_flow"]
        power = params["nominal_power"] * part_load_power_fraction(
            fraction, c1=params["c1"], c2=params["c2"], c3=params["c3"], c4=params["c4"])
        mass_flow = AIR_DENSITY_KG_PER_M3 * flow
        return {
            "outlet_air_temperature": inputs["inlet_air_temperature"]
            + fan_heat_rise_k(params["impeller_heat_share"], power, mass_flow),
            "outlet_air_mass_flow": mass_flow,
            "electric_power": power,
        }
