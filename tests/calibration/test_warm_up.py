"""Every simulated window starts warmed up: a controller's integral and the thermal masses in the
state the operation before the window leaves (the data's first day repeated before its first step),
not empty. Seed 0's truth is a slow heating loop (K_p ≈ 0.012 /K, T_i ≈ 1,850 s) still winding down
from the day setpoint at midnight, where the data starts: a cold start misses its first six hours
by 5.7 K (coil outlet air; 2.6 K with the conditional-integration controller of before) and bent the
point fit's time constants to match that transient."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from case_study import EX
from case_study_truth import CaseStudyTruth

from service.calibration.run import calibrate

SIX_HOURS = slice(0, 36)
AIR, WATER = EX + "coil_outlet_air_temperature_sensor", EX + "coil_outlet_water_temperature_sensor"


@pytest.fixture(scope="module")
def seed0(tmp_path_factory):
    return CaseStudyTruth(tmp_path_factory.mktemp("warm"), seed=0)


def _rmse(observed, simulated, span=slice(None)):
    return float(np.sqrt(np.nanmean((observed[span] - simulated[span]) ** 2)))


def test_the_truth_s_parameters_match_the_data_from_its_first_step(seed0):
    """Warmed up, the truth misses the first six hours by 0.5 K (air) and 0.6 K (water), against 5.7
    and 9.8 K cold: not by the noise (0.1 K), since the warm-up repeats the first day where the truth
    ran another one, and this slow loop's integral remembers it for hours (the valve is 0.07 off at
    midnight, 0.01 by six)."""
    observed = seed0.md.observed(seed0.train)
    warmed = seed0.md.simulate_targets(seed0.train, seed0.true_theta[None, :])
    cold = dataclasses.replace(seed0.md, warmup_s=0.0).simulate_targets(seed0.train, seed0.true_theta[None, :])
    for node in (AIR, WATER):
        assert _rmse(observed[node], warmed[node][0], SIX_HOURS) < 0.8, node
        assert _rmse(observed[node], cold[node][0], SIX_HOURS) > 2.0, node  # what the warm-up removes


def test_a_window_after_the_data_s_start_warms_up_on_the_data_before_it(seed0):
    """The test day simulated on its own (warmed up over the training day) is the continuation of
    the run from the data's start, to a small fraction of the noise."""
    md, theta = seed0.md, seed0.true_theta[None, :]
    alone = md.simulate_targets(seed0.test, theta)
    joined = slice(seed0.train.start, seed0.test.stop)
    continued = {node: values[:, seed0.test.start - joined.start:] for node, values in md.simulate_targets(joined, theta).items()}
    for node in (AIR, WATER, EX + "valve_position_sensor"):
        assert np.max(np.abs(alone[node] - continued[node])) < 0.02, node


def test_a_window_at_the_data_s_start_is_scored_once_its_guessed_start_state_is_forgotten(seed0):
    """At the data's start the warm-up's integral is a guess: with the truth's own parameters the
    model misses hours 1–6 by 4–6 times the noise (coil outlet air 0.46 K, water 0.60 K, valve 0.034)
    and the rest of the day by about the noise (1.0–1.4 times), so the training day is scored from
    its seventh hour.
    The test day, warmed up on the measured training day, is scored after an hour; a window two hours
    into the data after what is left of the six."""
    md = seed0.md
    assert md.unscored_start_s(seed0.train) == 6 * 3600
    assert md.unscored_start_s(seed0.test) == 3600
    assert md.unscored_start_s(slice(12, 144)) == 4 * 3600
    observed = md.observed(seed0.train)
    truth = md.simulate_targets(seed0.train, seed0.true_theta[None, :])
    for node, noise in ((AIR, 0.1), (WATER, 0.1), (EX + "valve_position_sensor", 0.005)):
        assert _rmse(observed[node], truth[node][0], slice(6, 36)) > 3 * noise, node
        assert _rmse(observed[node], truth[node][0], slice(36, None)) < 1.5 * noise, node
        scored = np.isfinite(seed0.problem.observed[node])
        assert not scored[:36].any() and scored[36:].all(), node


def test_point_calibration_on_a_start_in_mid_transient_predicts_the_next_day_within_the_noise(seed0):
    outcome = calibrate(seed0.store, "case", seed0.truth.path, train=("2026-01-12", "2026-01-12T23:59"),
                        test=("2026-01-13", None), seed=0)
    test = outcome.record.metrics["test"]
    assert test[AIR].rmse < 0.2  # noise 0.1 K; 0.42 K from a cold start
    assert test[EX + "valve_position_sensor"].rmse < 0.02  # noise 0.005; 0.08 from a cold start


def test_the_warm_up_is_as_long_as_the_model_s_slowest_state_needs():
    """A day with a PI loop; none for static components (the FLEXLAB unit's coils, mixing box and
    fan); five of its slowest time constants for a sensor lag added to them. The start memory (what
    is left unscored after a guessed start) six hours with a PI loop, none without."""
    from service.components.hot_water_loop import HotWaterLoop
    from service.data.model_series import model_start_memory_s, model_warmup_s
    from service.graph.store import GraphStore
    from service.model.assembly import assemble
    from service.model.effect_splicing import EffectRequest
    from service.resources import examples_dir

    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    store.load_model("flexlab", examples_dir() / "flexlab_ahu" / "model.ttl")
    assert model_warmup_s(assemble(store, "case")) == 86400.0
    assert model_start_memory_s(assemble(store, "case")) == 6 * 3600.0
    assert HotWaterLoop.settling_time_s() == 86400.0  # standing water forgets its start within a day
    flexlab = assemble(store, "flexlab")
    assert model_warmup_s(flexlab) == 0.0 and model_start_memory_s(flexlab) == 0.0
    sensor = next(flexlab.measurement(c).node for c in flexlab.targets)
    lagged = assemble(store, "flexlab", extra_effects=[EffectRequest("SensorLag", sensor)])
    assert model_warmup_s(lagged) == 5 * 1800.0
