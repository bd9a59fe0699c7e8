"""An effect at its null passes its host's output on to the last bit: the diagnosis's shared model
(service/diagnosis/shared_runs.py) holds every other candidate's effect at its null, so an effect
that rounds there makes a candidate's evidence depend on which candidates share its model (the
number of worker processes)."""

import numpy as np


def test_effects_are_the_exact_identity_at_their_null(effect_class, inputs_for):
    cls, n, dt_s = effect_class, 400, 900.0
    rng = np.random.default_rng(0)
    params = {p.name: np.full(n, p.null if p.null is not None else p.default) for p in cls.parameters}
    typical = inputs_for(cls, n)

    def inputs_at() -> dict[str, np.ndarray]:  # temperatures of either sign and any magnitude, others scaled
        return {name: (rng.uniform(-25.0, 45.0, n) if port.unit == "degC" else typical[name] * rng.uniform(0.0, 2.0, n))
                for name, port in ((p.name, p) for p in cls.inputs)}

    model = cls()
    first = inputs_at()
    state = model.initial_state(dict(params), first, dt_s)
    for k in range(6):
        inputs = first if k == 0 else inputs_at()
        out = model.step(dict(params), dict(inputs), state, dt_s)["value_out"]
        np.testing.assert_array_equal(out, inputs["value_in"], err_msg=f"{cls.__name__} at step {k}")
