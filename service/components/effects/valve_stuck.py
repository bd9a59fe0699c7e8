"""A valve (or damper) that does not follow its command: stuck at a fixed position."""

from __future__ import annotations

from service.components.component import Parameter, Port, SplicedEffect

__all__ = ["ValveStuck"]


class ValveStuck(SplicedEffect):
    """u_eff = (1 − w) · u + w · s   [1]

    u the commanded position, s the position the actuator is stuck at, w the share of the time-
    averaged response that ignores the command (w = 1: fully stuck at s; 0 < w < 1: a slipping
    linkage or an actuator that reaches only part of its travel). Null: w = 0 (s then has no effect).
    """

    stem_position_parameter = "stuck_position"
    inputs = (Port("value_in", "1", "commanded position"),)
    outputs = (Port("value_out", "1", "effective position"),)
    parameters = (
        Parameter("stuck_weight", "1", 0.0, 0.0, 1.0, "share of the response that ignores the command, w", null=0.0,
                  attainable=(1.0,)),
        Parameter("stuck_position", "1", 0.5, 0.0, 1.0, "position the actuator is stuck at, s", attainable=(0.0, 1.0)),
    )

    def step(self, params, inputs, state, dt_s):
        weight = params["stuck_weight"]
        return {"value_out": (1.0 - weight) * inputs["value_in"] + weight * params["stuck_position"]}
