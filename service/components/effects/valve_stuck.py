"""A valve (or damper) that does not follow its command: stuck at a fixed position."""

from __future__ import annotations

from service.components.actuator import DEAD_BAND_PARAMETER, act_on_stem
from service.components.component import Parameter, Port, SplicedEffect

__all__ = ["ValveStuck"]


class ValveStuck(SplicedEffect):
    """x_eff = (1 − w) · x + w · s   [1]

    x the position the command sets, s the position the stem is stuck at, w the share of the time-
    averaged response that ignores the command (w = 1: fully stuck at s; 0 < w < 1: a slipping
    linkage or an actuator that reaches only part of its travel). Null: w = 0 (s then has no effect).
    Where the host maps the command through an actuator dead band (``valve_dead_band``, read from the
    host), x and s are stem positions past it (:mod:`service.components.actuator`); elsewhere x is
    the command.
    """

    stem_position_parameter = "stuck_position"
    host_parameters = (DEAD_BAND_PARAMETER,)
    inputs = (Port("value_in", "1", "commanded position"),)
    outputs = (Port("value_out", "1", "effective position"),)
    parameters = (
        Parameter("stuck_weight", "1", 0.0, 0.0, 1.0, "share of the response that ignores the command, w", null=0.0,
                  attainable=(1.0,)),
        Parameter("stuck_position", "1", 0.5, 0.0, 1.0, "position the actuator is stuck at, s", attainable=(0.0, 1.0)),
    )

    def step(self, params, inputs, state, dt_s):
        weight, stuck = params["stuck_weight"], params["stuck_position"]
        return {"value_out": act_on_stem(inputs["value_in"], params,
                                         lambda stem: (1.0 - weight) * stem + weight * stuck)}
