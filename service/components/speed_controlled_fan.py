"""Fan with a variable-speed drive, driven by a logged speed command: flow from speed, power from the
part-load curve of :class:`service.components.fan.Fan`."""

from __future__ import annotations

import numpy as np

from service.components.component import AIR_DENSITY_KG_PER_M3, ComponentModel, Port
from service.components.fan import Fan, fan_heat_rise_k, part_load_power_fraction

__all__ = ["SpeedControlledFan"]


class SpeedControlledFan(ComponentModel):
    """V̇ = s·V̇_nom [m³/s],  ṁ = ρ_air·V̇ [kg/s],  P = P_nom·(c1 + c2·s + c3·s² + c4·s³) [W]

    s the speed command (0–1, clipped; a VFD's logged output frequency over its nominal one). The
    flow is proportional to the speed (fan affinity law at a fixed system curve, i.e. fixed damper
    positions), so the flow fraction of the part-load curve is s itself. The impeller's losses heat
    the air as in :class:`service.components.fan.Fan`, whose parameters, defaults and bounds these are.
    """

    inputs = (
        Port("speed", "1", "fan speed command, s"),
        Port("inlet_air_temperature", "degC", "air temperature at the fan inlet"),
    )
    outputs = Fan.outputs
    parameters = Fan.parameters
    #: The nominal flow sets the air flow here, which the targets see: only the curve is the power's.
    power_curve_parameters = ("nominal_power", "c1", "c2", "c3", "c4")
    parameters_fixed_by_measurement = classmethod(Fan.parameters_fixed_by_measurement.__func__)

    def step(self, params, inputs, state, dt_s):
        speed = np.minimum(np.maximum(inputs["speed"], 0.0), 1.0)
        power = params["nominal_power"] * part_load_power_fraction(
            speed, c1=params["c1"], c2=params["c2"], c3=params["c3"], c4=params["c4"])
        mass_flow = AIR_DENSITY_KG_PER_M3 * params["nominal_air_flow"] * speed
        return {
            "outlet_air_temperature": inputs["inlet_air_temperature"]
            + fan_heat_rise_k(params["impeller_heat_share"], power, mass_flow),
            "outlet_air_mass_flow": mass_flow,
            "electric_power": power,
        }
