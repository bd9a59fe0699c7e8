"""Flow through a valve commanded shut: seat leakage or an open bypass."""

from __future__ import annotations

from service.components.component import Parameter, Port, SplicedEffect

__all__ = ["ValveLeakage"]


class ValveLeakage(SplicedEffect):
    """u_eff = u + λ · (1 − u)   [1]

    u the commanded position (0 shut … 1 open), λ the leak as the stem position whose flow a shut
    valve passes: on a linear valve the share λ of the open flow coefficient (a parallel leak path
    Kv_leak = λ·Kv), on a valve with characteristic φ the share φ(λ). Null: λ = 0. The flow opening
    changes, not the stem: the host's position feedback reads the command (the signature's
    ``readings_unchanged``). Behind an actuator dead band u₀ a leak λ ≤ u₀ cannot be told from a
    tight valve (``docs/components.md``).
    """

    stem_position_parameter = "leakage_fraction"
    inputs = (Port("value_in", "1", "commanded valve position"),)
    outputs = (Port("value_out", "1", "effective valve position"),)
    parameters = (
        Parameter("leakage_fraction", "1", 0.0, 0.0, 0.8, "leak as the stem position whose flow it passes, λ", null=0.0),
    )

    def step(self, params, inputs, state, dt_s):
        position = inputs["value_in"]
        return {"value_out": position + params["leakage_fraction"] * (1.0 - position)}
