"""Bayesian (Kennedy–O'Hagan) calibration on the synthetic zone: posterior, convergence, predictive coverage.

Two fits, shared by the tests below (each takes a few seconds on one core):
  * the model is right: θ = (UA, C, P) with η fixed, zone temperature at 10-min steps, GP over time;
  * the data carry a daily sinusoid of 0.5 K that the model lacks, GP over the time of day.
Test windows are the two days after the training day (288 and 144 points).
"""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_zone import DAY_S, NAMES, TRUTH, zone_windows

from service.calibration.bayesian import BayesianCalibrator
from service.calibration.metrics import target_metrics
from service.calibration.problem import CalibrationProblem

ESTIMATE = ("UA_W_per_K", "C_J_per_K", "heater_power_W")
TRUE_THETA = TRUTH[[NAMES.index(name) for name in ESTIMATE]]
KEY = "zone_temperature"


def pooled_metrics(fit, windows, level):
    """Metrics over all test windows at once, with one central interval."""
    predictions = [fit.predict(window, n_draws=300) for window in windows]
    observed = np.concatenate([w.observed[KEY] for w in windows])
    median = np.concatenate([p.median[KEY] for p in predictions])
    bounds = [np.concatenate([p.interval(KEY, level)[i] for p in predictions]) for i in (0, 1)]
    return target_metrics(observed, median, n_parameters=3, intervals={level: tuple(bounds)}, unit="degC"), predictions


@pytest.fixture(scope="module")
def right_model():
    train, *tests = zone_windows(3, steps_per_day=144, seed=3, estimate=ESTIMATE, targets=(KEY,))
    fit = BayesianCalibrator(n_temperatures=2, max_steps=3000, random_state=0, progress=False).fit(train)
    return train, tests, fit


@pytest.fixture(scope="module")
def missing_physics():
    train, *tests = zone_windows(
        3, steps_per_day=72, seed=3, estimate=ESTIMATE, targets=(KEY,), disturbance_k=0.5, time_of_day_input=True
    )
    fit = BayesianCalibrator(n_temperatures=2, max_steps=3000, random_state=0, progress=False).fit(train)
    return train, tests, fit


def test_chain_stops_by_the_20_iat_rule(right_model):
    _, _, fit = right_model
    assert fit.converged_
    assert fit.n_steps_ >= 20 * fit.iat_
    history = fit.convergence_.iat_history
    assert abs(history[-1] - history[-2]) < 0.05 * history[-1]
    n_walkers = 16  # the default: max(16, 2 · n_dim + 2) with n_dim = 3 + 3
    expected = n_walkers * len(range(fit.convergence_.burn_in + fit.convergence_.thin - 1, fit.n_steps_, fit.convergence_.thin))
    assert fit.samples_.shape == (expected, 3) and fit.hyper_samples_.shape == (expected, 3)
    assert 0.2 < fit.acceptance_ < 0.8 and fit.swap_rate_.shape == (1,) and fit.swap_rate_[0] > 0.1


def test_68_percent_intervals_contain_the_truth(right_model):
    _, _, fit = right_model
    assert np.all(fit.quantile16_ <= TRUE_THETA) and np.all(TRUE_THETA <= fit.quantile84_)
    assert np.all(fit.quantile16_ < fit.median_) and np.all(fit.median_ < fit.quantile84_)
    np.testing.assert_allclose(fit.map_, TRUE_THETA, rtol=0.05)


def test_noise_is_learned_and_the_discrepancy_stays_small_when_the_model_is_right(right_model):
    train, _, fit = right_model
    scale = train.target_scales[KEY]
    noise = np.exp(np.median(fit.hyper_samples_[:, fit.hyper_names_.index(f"{KEY}:log_noise")])) * scale
    amplitude = np.exp(np.median(fit.hyper_samples_[:, fit.hyper_names_.index(f"{KEY}:log_amplitude")])) * scale
    assert noise == pytest.approx(0.1, rel=0.15)  # the sensor noise of the synthetic data
    assert amplitude < 0.3 * noise


def test_test_window_coverage_at_90_percent_within_5_percent(right_model):
    _, tests, fit = right_model
    metrics, predictions = pooled_metrics(fit, tests, 0.9)
    assert metrics.n == 288
    assert abs(metrics.coverage[0].ace) <= 0.05
    assert metrics.rmse == pytest.approx(0.1, rel=0.2)
    assert predictions[0].draws[KEY].shape == (300, 144)


def test_discrepancy_absorbs_structure_the_model_lacks(missing_physics, right_model):
    train, tests, fit = missing_physics
    metrics, predictions = pooled_metrics(fit, tests, 0.9)
    assert abs(metrics.coverage[0].ace) <= 0.10
    assert metrics.rmse < 0.15  # the disturbance (0.35 K rms) is predicted, only the noise is left
    # the conditioned discrepancy follows the missing sinusoid on the test days
    hours = np.arange(72) * DAY_S / 72
    disturbance = 0.5 * np.sin(2 * np.pi * hours / DAY_S)
    assert np.corrcoef(predictions[0].discrepancy_mean[KEY], disturbance)[0, 1] > 0.9
    # the point fit's residuals show the missing structure; with the right model they are white
    lag1_missing = target_metrics(train.observed[KEY], fit.point_calibrator_.prediction_[KEY]).lag1_autocorrelation
    right_train, _, right_fit = right_model
    lag1_right = target_metrics(right_train.observed[KEY], right_fit.point_calibrator_.prediction_[KEY]).lag1_autocorrelation
    assert lag1_missing > 0.6 and abs(lag1_right) < 0.2


def test_a_seeded_fit_is_reproducible_and_a_capped_run_is_not_converged():
    (train,) = zone_windows(1, steps_per_day=48, seed=5, estimate=ESTIMATE, targets=(KEY,))
    settings = dict(n_temperatures=2, max_steps=40, check_interval=20, random_state=11, progress=False)
    first = BayesianCalibrator(**settings).fit(train)
    second = BayesianCalibrator(**settings).fit(train)
    np.testing.assert_array_equal(first.samples_, second.samples_)
    np.testing.assert_array_equal(first.hyper_samples_, second.hyper_samples_)
    assert not first.converged_ and first.n_steps_ == 40
    np.testing.assert_array_equal(first.predict(train, n_draws=20).draws[KEY], second.predict(train, n_draws=20).draws[KEY])


def test_predict_checks_the_window_and_the_interval_level(right_model):
    train, tests, fit = right_model
    other, *_ = zone_windows(1, steps_per_day=144, seed=3, estimate=("UA_W_per_K", "C_J_per_K"), targets=(KEY,))
    with pytest.raises(ValueError, match="parameters differ from the calibrated parameters"):
        fit.predict(other)
    with pytest.raises(ValueError, match=r"interval level 1.2 must lie in \(0, 1\)"):
        fit.predict(tests[0], n_draws=10).interval(KEY, 1.2)
    with pytest.raises(ValueError, match="gp_inputs='space': expected 'auto', 'time' or column indices"):
        BayesianCalibrator(gp_inputs="space", progress=False).fit(train)
    with pytest.raises(ValueError, match=r"gp_inputs=\[0\] selects columns, but the problem has no gp_inputs"):
        BayesianCalibrator(gp_inputs=[0], progress=False).fit(train)


def test_a_time_index_discrepancy_is_placed_where_the_predicted_window_lies():
    """With the GP over the time index, predicting the training steps again (alone, or as the head of
    a longer window) conditions the discrepancy on those very steps: the median follows the slow
    structure the model lacks; placed after the training window it would not."""
    steps = np.arange(100, dtype=float)
    truth = 2 * np.sin(steps / 6) + 1 + 0.5 * np.sin(steps / 25)  # the model lacks the slow sinusoid
    observed = truth + np.random.default_rng(0).normal(0, 0.05, steps.size)

    def window(n):
        def simulate(theta):
            return {"y": theta[:, :1] * np.sin(steps[:n] / 6)[None] + theta[:, 1:2]}
        return CalibrationProblem(("a", "b"), np.array([0.0, -3.0]), np.array([5.0, 3.0]), simulate,
                                  {"y": observed[:n]}, units={"y": "degC"})

    train, joined = window(80), window(100)
    fit = BayesianCalibrator(gp_inputs="time", max_steps=400, n_temperatures=2, random_state=0, progress=False).fit(train)

    def rmse_on_training_steps(predictive):
        return float(np.sqrt(np.mean((predictive.median["y"][:80] - observed[:80]) ** 2)))

    in_place = rmse_on_training_steps(fit.predict(joined, n_draws=100, steps_from_training_start=0))
    assert in_place < 0.1  # noise 0.05 K, slow sinusoid 0.35 K rms
    assert rmse_on_training_steps(fit.predict(train, n_draws=100, steps_from_training_start=0)) == pytest.approx(in_place, rel=0.3)
    assert rmse_on_training_steps(fit.predict(joined, n_draws=100)) > 3 * in_place  # read as the steps after training


def test_exact_data_start_the_sampler_from_the_plain_ball():
    """Noise-free data the model reproduces: the point fit's residuals and standard errors are zero;
    its correlation is 0 off the diagonal (not NaN) and the walkers still start inside the prior."""
    steps = np.arange(80, dtype=float)

    def simulate(theta):
        return {"y": theta[:, :1] * np.sin(steps / 6)[None] + theta[:, 1:2]}

    exact = CalibrationProblem(("a", "b"), np.array([0.0, -3.0]), np.array([5.0, 3.0]), simulate,
                               {"y": simulate(np.array([[2.0, 1.0]]))["y"][0]}, units={"y": "degC"},
                               default=np.array([2.0, 1.0]))
    fit = BayesianCalibrator(max_steps=100, n_temperatures=2, random_state=0, progress=False).fit(exact)
    point = fit.point_calibrator_
    assert np.all(point.standard_errors_ == 0.0) and np.array_equal(point.correlation_, np.eye(2))
    assert np.allclose(fit.median_, [2.0, 1.0], atol=0.01)


def test_sampling_reports_how_far_it_is_after_each_convergence_check():
    """A job's progress during a Bayesian run (HTTP shows it while the job runs): one message per
    IAT check, the step counts rising by the check interval, the last one the chain's length."""
    train, *_ = zone_windows(1, steps_per_day=72, seed=3, estimate=ESTIMATE, targets=(KEY,))
    heard: list[str] = []
    fit = BayesianCalibrator(n_temperatures=2, max_steps=300, check_interval=100, random_state=0, progress=False,
                             on_check=heard.append).fit(train)
    assert len(heard) == len(fit.convergence_.iat_history) == 3
    assert [message.split()[2] for message in heard] == ["100", "200", "300"]
    assert all(message.startswith("sampling: step ") and "at most 300" in message for message in heard)
