"""Matérn 3/2 GP against direct dense formulas (scipy's multivariate normal, explicit inverses)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from service.calibration.matern_gp import InputDistances, conditional, log_marginal_likelihood, matern32


def direct_kernel(x1, x2, amplitude, length_scales):
    r = np.sqrt((((x1[:, None, :] - x2[None, :, :]) / length_scales) ** 2).sum(-1))
    return amplitude**2 * (1 + np.sqrt(3) * r) * np.exp(-np.sqrt(3) * r)


def test_matern32_values():
    assert matern32(0.0) == 1.0
    r = 0.7
    assert matern32(r) == pytest.approx((1 + np.sqrt(3) * r) * np.exp(-np.sqrt(3) * r), rel=1e-14)


@pytest.mark.parametrize("n_inputs", [1, 3])
def test_covariance_matches_the_direct_formula_for_every_set(n_inputs):
    rng = np.random.default_rng(1)
    x1, x2 = rng.uniform(size=(7, n_inputs)), rng.uniform(size=(5, n_inputs))
    amplitude = np.array([0.5, 2.0])
    length_scales = rng.uniform(0.1, 1.0, size=(2, n_inputs))
    batch = InputDistances(x1, x2).covariance(amplitude, length_scales)
    for s in range(2):
        np.testing.assert_allclose(batch[s], direct_kernel(x1, x2, amplitude[s], length_scales[s]), rtol=1e-12)


def test_regular_grid_uses_few_distinct_distances_and_stays_exact():
    x = np.linspace(0.0, 1.0, 144)
    distances = InputDistances(x)
    assert distances._unique.size <= 2 * 144  # rounding merges equal lags of the regular grid
    k = distances.covariance(np.array([1.3]), np.array([[0.05]]))[0]
    np.testing.assert_allclose(k, direct_kernel(x[:, None], x[:, None], 1.3, np.array([0.05])), rtol=1e-10, atol=1e-15)


def test_log_marginal_likelihood_equals_the_dense_gaussian_log_density():
    rng = np.random.default_rng(2)
    x = rng.uniform(size=(40, 2))
    residuals = rng.normal(size=(3, 40))
    amplitude = np.array([0.3, 1.0, 3.0])
    length_scales = np.array([[0.1, 0.5], [0.3, 0.3], [1.0, 0.05]])
    noise = np.array([0.1, 0.5, 0.01])
    values = log_marginal_likelihood(residuals, InputDistances(x), amplitude, length_scales, noise)
    for s in range(3):
        covariance = direct_kernel(x, x, amplitude[s], length_scales[s]) + noise[s] ** 2 * np.eye(40)
        expected = multivariate_normal(np.zeros(40), covariance).logpdf(residuals[s])
        assert values[s] == pytest.approx(expected, rel=1e-9)


def test_one_input_state_space_likelihood_equals_the_dense_density():
    """Unsorted, irregular inputs with a repeated point, hyperparameters across the prior's range."""
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(size=25), [0.5, 0.5]])
    residuals = rng.normal(size=(5, x.size))
    amplitude = np.array([1e-3, 0.3, 1.0, 10.0, 2.0])
    length_scales = np.array([[0.02], [0.1], [10.0], [0.3], [0.02]])
    noise = np.array([1e-3, 0.5, 0.1, 1e-3, 2.0])
    values = log_marginal_likelihood(residuals, InputDistances(x), amplitude, length_scales, noise, "state_space")
    dense = log_marginal_likelihood(residuals, InputDistances(x), amplitude, length_scales, noise, "dense")
    np.testing.assert_allclose(values, dense, rtol=1e-8)
    for s in range(5):
        covariance = direct_kernel(x[:, None], x[:, None], amplitude[s], length_scales[s]) + noise[s] ** 2 * np.eye(x.size)
        expected = multivariate_normal(np.zeros(x.size), covariance).logpdf(residuals[s])
        assert values[s] == pytest.approx(expected, rel=1e-8)


@pytest.mark.parametrize("method", ["dense", "state_space"])
def test_a_singular_covariance_gives_minus_infinity_for_that_set_only(method):
    x = np.zeros((5, 1))  # identical inputs: K is rank one, singular without noise
    values = log_marginal_likelihood(
        np.zeros((2, 5)), InputDistances(x), np.array([1.0, 1.0]), np.ones((2, 1)), np.array([0.0, 0.1]), method
    )
    assert values[0] == -np.inf and np.isfinite(values[1])


def test_conditional_matches_the_textbook_formulas():
    rng = np.random.default_rng(3)
    x, x_star = rng.uniform(size=(30, 1)), np.linspace(-0.2, 1.2, 11)[:, None]
    y = np.sin(6 * x[:, 0]) + 0.05 * rng.normal(size=30)
    amplitude, length, noise = 1.0, 0.2, 0.05
    mean, covariance = conditional(
        y[None, :], InputDistances(x), InputDistances(x, x_star), InputDistances(x_star),
        np.array([amplitude]), np.array([[length]]), np.array([noise]),
    )
    k = direct_kernel(x, x, amplitude, np.array([length])) + noise**2 * np.eye(30)
    k_star = direct_kernel(x, x_star, amplitude, np.array([length]))
    k_star_star = direct_kernel(x_star, x_star, amplitude, np.array([length]))
    np.testing.assert_allclose(mean[0], k_star.T @ np.linalg.solve(k, y), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(covariance[0], k_star_star - k_star.T @ np.linalg.solve(k, k_star), atol=1e-10)
    # inside the data the GP follows sin(6x); far outside the variance returns to σ_f²
    assert abs(mean[0][5] - np.sin(6 * 0.5)) < 0.1
    assert covariance[0][0, 0] > 0.5 * amplitude**2 > covariance[0][5, 5]


def test_shape_errors_name_the_shapes():
    with pytest.raises(ValueError, match=r"length_scales has shape \(2, 2\), expected \(2, 1\)"):
        InputDistances(np.zeros(3)).covariance(np.ones(2), np.ones((2, 2)))
    with pytest.raises(ValueError, match="residuals have 4 points but the training distances are"):
        log_marginal_likelihood(np.zeros((1, 4)), InputDistances(np.zeros(3)), np.ones(1), np.ones((1, 1)), np.ones(1))
    with pytest.raises(ValueError, match="state-space likelihood needs one input"):
        log_marginal_likelihood(np.zeros((1, 3)), InputDistances(np.zeros((3, 2))), np.ones(1), np.ones((1, 2)), np.ones(1), "state_space")
