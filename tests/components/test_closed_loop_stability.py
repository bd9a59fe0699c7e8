"""The priors keep the simulated heating loop free of the sampling limit cycle (the brief: wide
PI-gain priors make the loop chaotic)."""

import numpy as np

from service.data.synthetic_operation import case_study_operation
from service.model.assembly import assemble
from service.model.simulator import Simulator


def test_no_draw_from_the_prior_oscillates_at_the_sampling_frequency(case_store):
    model = assemble(case_store, "case")
    lower = np.array([r.spec.lower for r in model.estimated_parameters])
    upper = np.array([r.spec.upper for r in model.estimated_parameters])
    theta = lower + np.random.default_rng(0).random((200, lower.size)) * (upper - lower)
    operation = case_study_operation(n_days=2, step_s=120.0, seed=0)  # the default internal step
    boundary = {c: operation.series[model.measurement(c).series_id] for c in model.boundary_inputs}
    controller = next(c for c in model.components if "PIController" in c)
    signal = Simulator(model, 120.0).run(boundary, theta, record=[(controller, "control_signal")]).outputs[
        (controller, "control_signal")][:, 30:]
    increments = np.diff(signal, axis=1)
    alternating = (increments[:, 1:] * increments[:, :-1] < 0) & (np.abs(increments[:, 1:]) > 0.1)
    assert alternating.mean(axis=1).max() < 0.02
