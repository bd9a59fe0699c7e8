"""Kennedy–O'Hagan likelihood: equals the dense Gaussian density per target, one simulate call, priors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from service.calibration.koh_likelihood import HyperparameterBounds, KennedyOHaganLikelihood
from service.calibration.problem import CalibrationProblem

N = 30
T = np.arange(N, dtype=float)


class CountingSimulate:
    def __init__(self):
        self.members: list[int] = []

    def __call__(self, theta):
        self.members.append(theta.shape[0])
        a, b = theta[:, :1], theta[:, 1:2]
        return {"temperature": a + b * np.sin(T / 5.0), "power": 100.0 * a * np.ones(N)}


def make_problem(simulate=None, gaps=True):
    rng = np.random.default_rng(0)
    observed = {
        "temperature": 1.0 + 0.5 * np.sin(T / 5.0) + 0.1 * rng.normal(size=N),
        "power": 100.0 + 5.0 * rng.normal(size=N),
    }
    if gaps:  # the targets are measured at different steps: one GP call each
        observed["temperature"][[3, 7]] = np.nan
    return CalibrationProblem(
        parameter_names=("a", "b"), lower=np.array([0.0, 0.0]), upper=np.array([2.0, 1.0]),
        simulate=simulate or CountingSimulate(), observed=observed,
        target_scales={"temperature": 0.5, "power": 10.0},
    )


def dense_log_likelihood(problem, theta, hyper):
    """Σ_targets log N(y − η(θ) | 0, σ_f² matern32 + σ_n² I), hyper = per target (log a, log ℓ, log n)."""
    outputs = problem.simulate(theta[None, :])
    total = 0.0
    for k, key in enumerate(problem.target_keys):
        log_a, log_l, log_n = hyper[3 * k : 3 * k + 3]
        scale = problem.target_scales[key]
        mask = np.isfinite(problem.observed[key])
        x = T[mask] / (N - 1)
        r = np.abs(x[:, None] - x[None, :]) / np.exp(log_l)
        kernel = (np.exp(log_a) * scale) ** 2 * (1 + np.sqrt(3) * r) * np.exp(-np.sqrt(3) * r)
        covariance = kernel + (np.exp(log_n) * scale) ** 2 * np.eye(mask.sum())
        residual = problem.observed[key][mask] - outputs[key][0, mask]
        total += multivariate_normal(np.zeros(mask.sum()), covariance).logpdf(residual)
    return total


@pytest.mark.parametrize("gaps", [True, False], ids=["targets apart", "targets in one GP call"])
def test_log_likelihood_is_the_dense_gaussian_density_summed_over_targets(gaps):
    problem = make_problem(gaps=gaps)
    likelihood = KennedyOHaganLikelihood(problem)
    assert likelihood.n_dim == 2 + 2 * 3
    assert likelihood.names[2:] == (
        "temperature:log_amplitude", "temperature:log_length_scale:time", "temperature:log_noise",
        "power:log_amplitude", "power:log_length_scale:time", "power:log_noise",
    )
    batch = np.array([
        [1.0, 0.5, np.log(0.1), np.log(0.2), np.log(0.2), np.log(0.05), np.log(0.5), np.log(0.5)],
        [1.2, 0.3, np.log(1.0), np.log(0.05), np.log(0.3), np.log(2.0), np.log(1.0), np.log(0.1)],
    ])
    log_prior, log_likelihood = likelihood.evaluate(batch)
    for row, value in zip(batch, log_likelihood):
        assert value == pytest.approx(dense_log_likelihood(problem, row[:2], row[2:]), rel=1e-9)
    widths = np.concatenate([[2.0, 1.0], np.log([1e4, 500.0, 2000.0] * 2)])
    np.testing.assert_allclose(log_prior, -np.sum(np.log(widths)))
    np.testing.assert_allclose(likelihood.log_posterior(batch), log_prior + log_likelihood)


def test_one_simulate_call_per_batch_and_none_for_members_outside_the_prior():
    simulate = CountingSimulate()
    likelihood = KennedyOHaganLikelihood(make_problem(simulate))
    inside = np.array([1.0, 0.5] + [np.log(0.1), np.log(0.2), np.log(0.2)] * 2)
    outside_theta = inside.copy()
    outside_theta[0] = 2.5
    outside_hyper = inside.copy()
    outside_hyper[4] = np.log(50.0)  # length scale above its 10 bound
    log_prior, log_likelihood = likelihood.evaluate(np.stack([inside, outside_theta, inside, outside_hyper]))
    assert simulate.members == [2]
    assert np.isneginf(log_prior[[1, 3]]).all() and np.isneginf(log_likelihood[[1, 3]]).all()
    assert np.isfinite(log_likelihood[[0, 2]]).all()


def test_non_finite_simulation_gives_minus_infinity():
    def broken(theta):
        outputs = CountingSimulate()(theta)
        outputs["power"] = np.where(theta[:, :1] > 1.5, np.nan, outputs["power"])
        return outputs

    likelihood = KennedyOHaganLikelihood(make_problem(broken))
    row = [np.log(0.1), np.log(0.2), np.log(0.2)] * 2
    _, log_likelihood = likelihood.evaluate(np.array([[1.0, 0.5] + row, [1.8, 0.5] + row]))
    assert np.isfinite(log_likelihood[0]) and log_likelihood[1] == -np.inf


def test_long_series_are_thinned_to_an_evenly_spaced_subset():
    likelihood = KennedyOHaganLikelihood(make_problem(), max_points_per_target=10)
    index = likelihood.train_index["power"]
    assert index.size == 10 and index[0] == 0 and index[-1] == N - 1
    assert np.ptp(np.diff(index)) <= 1  # evenly spaced
    assert not np.isin([3, 7], likelihood.train_index["temperature"]).any()


def test_gp_inputs_are_scaled_to_the_training_window_and_checked():
    problem = make_problem()
    raw = np.column_stack([T * 600.0, np.cos(T)])
    likelihood = KennedyOHaganLikelihood(problem, raw)
    assert likelihood.input_names == ("gp_input0", "gp_input1")
    scaled = likelihood.scale_inputs(np.array([[0.0, -1.0], [2 * (N - 1) * 600.0, 1.0]]))
    assert scaled[0, 0] == 0.0 and scaled[1, 0] == pytest.approx(2.0)  # a following window lies in [1, 2]
    with pytest.raises(ValueError, match="gp input column 1 is constant"):
        KennedyOHaganLikelihood(problem, np.column_stack([T, np.ones(N)]))
    with pytest.raises(ValueError, match=r"batch has shape \(2, 3\), expected \(n_walkers, 8\)"):
        KennedyOHaganLikelihood(problem).evaluate(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"amplitude=\(1.0, 0.5\): need 0 < lower < upper"):
        HyperparameterBounds(amplitude=(1.0, 0.5))


def test_initial_ensemble_lies_inside_the_prior_near_the_point_estimate():
    likelihood = KennedyOHaganLikelihood(make_problem())
    walkers = likelihood.initial_ensemble(
        np.array([1.0, 0.999999]), {"temperature": 0.1, "power": 5.0}, 50, np.random.RandomState(0)
    )
    assert walkers.shape == (50, 8)
    assert np.isfinite(likelihood.log_prior(walkers)).all()
    assert np.abs(np.median(walkers[:, 0]) - 1.0) < 0.01
    assert np.median(walkers[:, 4]) == pytest.approx(np.log(0.2), abs=0.05)  # noise ≈ 0.1 / scale 0.5


def test_initial_ensemble_takes_the_shape_of_the_point_covariance():
    """Confounded parameters start along their ridge; a flat direction is capped at 10 % of the prior."""
    likelihood = KennedyOHaganLikelihood(make_problem())
    standard_errors = np.array([0.02, 5.0])  # b: far wider than its prior [0, 1]
    correlation = np.array([[1.0, -0.99], [-0.99, 1.0]])
    covariance = correlation * np.outer(standard_errors, standard_errors)
    walkers = likelihood.initial_ensemble(np.array([1.0, 0.5]), {"temperature": 0.1, "power": 5.0}, 4000,
                                          np.random.RandomState(0), covariance)
    theta = walkers[:, :2]
    assert np.corrcoef(theta.T)[0, 1] == pytest.approx(-0.99, abs=0.01)
    np.testing.assert_allclose(theta.std(axis=0), [0.02, 0.1], rtol=0.05)  # 0.1 = 10 % of b's prior width
    np.testing.assert_allclose(theta.mean(axis=0), [1.0, 0.5], atol=0.01)
    assert np.isfinite(likelihood.log_prior(walkers)).all()
    with pytest.raises(ValueError, match=r"theta_covariance has shape \(3, 3\), expected \(2, 2\)"):
        likelihood.initial_ensemble(np.array([1.0, 0.5]), {"temperature": 0.1, "power": 5.0}, 10,
                                    np.random.RandomState(0), np.eye(3))
