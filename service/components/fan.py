"""Fan with a measured air flow: polynomial part-load power curve (the paper's Sec. 5.1, Table 2)."""

from __future__ import annotations

import numpy as np

from service.components.component import AIR_DENSITY_KG_PER_M3, ComponentModel, Parameter, Port

__all__ = ["Fan", "part_load_power_fraction"]


def part_load_power_fraction(flow_fraction: np.ndarray, *, c1: np.ndarray, c2: np.ndarray, c3: np.ndarray,
                             c4: np.ndarray) -> np.ndarray:
    """c1 + c2·f + c3·f² + c4·f³ (Horner), clipped at 0, and 0 where f ≤ 0 (the fan is off: c1 is the
    curve's constant term while it runs, not a stand-by draw) [1]."""
    fraction = np.maximum(c1 + flow_fraction * (c2 + flow_fraction * (c3 + flow_fraction * c4)), 0.0)
    return np.where(flow_fraction > 0.0, fraction, 0.0)


class Fan(ComponentModel):
    """P = P_nom · (c1 + c2·f + c3·f² + c4·f³),  f = max(V̇, 0) / V̇_nom   [W];  P = 0 at f = 0 (off)

    ṁ = ρ_air · V̇ [kg/s] with ρ_air = 1.204 kg/m³; the air leaves at its inlet temperature (motor
    heat in the air stream is the FanMotorHeat effect, not part of this base model). Defaults: the
    ASHRAE 90.1 Appendix G variable-speed fan curve (c1..c4 = 0.0013, 0.1470, 0.9506, −0.0998,
    sum 0.9991 at f = 1); bounds wide enough for inlet-vane, variable-pitch and EC fans.
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
    )

    def step(self, params, inputs, state, dt_s):
        flow = np.maximum(inputs["air_volume_flow"], 0.0)
        fraction = flow / params["nominal_air_flow"]
        power = params["nominal_power"] * part_load_power_fraction(
            fraction, c1=params["c1"], c2=params["c2"], c3=params["c3"], c4=params["c4"])
        return {
            "outlet_air_temperature": inputs["inlet_air_temperature"],
            "outlet_air_mass_flow": AIR_DENSITY_KG_PER_M3 * flow,
            "electric_power": power,
        }
