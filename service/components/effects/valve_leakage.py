"""Flow through a valve commanded shut: seat leakage or an open bypass."""

from __future__ import annotations

from service.components.actuator import DEAD_BAND_PARAMETER, act_on_stem
from service.components.component import Parameter, Port, SplicedEffect

__all__ = ["ValveLeakage"]


class ValveLeakage(SplicedEffect):
    """x_eff = x + λ · (1 − x)   [1]

    x the stem position the command sets (0 shut … 1 open), λ the leak as the stem position whose
    flow a shut valve passes: on a linear valve the share λ of the open flow coefficient (a parallel
    leak path Kv_leak = λ·Kv), on a valve with characteristic φ the share φ(λ). Null: λ = 0. Where
    the host maps the command through an actuator dead band u₀ (``valve_dead_band``, read from the
    host), the leak acts past it, on the stem: the seat leaks whatever the actuator does (x and the
    command returned by :mod:`service.components.actuator`); elsewhere x is the command. The flow
    opening changes, not the reading: the host's position feedback reads the command (the
    signature's ``readings_unchanged``).
    """

    stem_position_parameter = "leakage_fraction"
    host_parameters = (DEAD_BAND_PARAMETER,)
    inputs = (Port("value_in", "1", "commanded valve position"),)
    outputs = (Port("value_out", "1", "effective valve position"),)
    parameters = (
        Parameter("leakage_fraction", "1", 0.0, 0.0, 0.8, "leak as the stem position whose flow it passes, λ", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        leak = params["leakage_fraction"]
        return {"value_out": act_on_stem(inputs["value_in"], params, lambda stem: stem + leak * (1.0 - stem))}
