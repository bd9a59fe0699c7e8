"""Parallel tempering on analytic targets: right moments, swaps that cross modes, reproducibility, the IAT rule."""

from __future__ import annotations

import numpy as np
import pytest

from service.calibration.parallel_tempering import ParallelTemperingSampler, geometric_betas

BOX = 10.0
MEAN = np.array([1.0, -2.0])
COVARIANCE = np.array([[1.0, 0.6], [0.6, 0.5]])
PRECISION = np.linalg.inv(COVARIANCE)


def uniform_box_prior(coords):
    return np.where(np.all(np.abs(coords) <= BOX, axis=1), 0.0, -np.inf)


def gaussian(coords):
    d = coords - MEAN
    return uniform_box_prior(coords), -0.5 * np.einsum("ni,ij,nj->n", d, PRECISION, d)


def two_modes(coords):
    """Equal modes at x = ±3 (σ = 0.4): a barrier of ≈ 28 nats, impassable for a local ensemble."""
    x = coords[:, 0]
    return uniform_box_prior(coords), np.logaddexp(-0.5 * ((x - 3) / 0.4) ** 2, -0.5 * ((x + 3) / 0.4) ** 2)


def run(fn, n_dim, betas, seed, max_steps, start, n_walkers=8, **kwargs):
    sampler = ParallelTemperingSampler(fn, n_walkers, n_dim, betas=betas, random_state=seed)
    rng = np.random.default_rng(seed)
    convergence = sampler.run(start + 0.1 * rng.standard_normal((n_walkers, n_dim)), max_steps, **kwargs)
    return sampler, convergence


def test_gaussian_moments_and_the_20_iat_stopping_rule():
    sampler, convergence = run(gaussian, 2, geometric_betas(3, 2), seed=1, max_steps=5000, start=MEAN)
    assert convergence.converged
    assert convergence.n_steps >= 20 * convergence.iat
    assert abs(convergence.iat_history[-1] - convergence.iat_history[-2]) < 0.05 * convergence.iat
    assert convergence.burn_in == int(np.ceil(2 * convergence.iat))
    samples = sampler.backend.get_chain(discard=convergence.burn_in, thin=convergence.thin, flat=True)
    np.testing.assert_allclose(samples.mean(axis=0), MEAN, atol=0.15)
    np.testing.assert_allclose(np.cov(samples.T), COVARIANCE, rtol=0.15, atol=0.05)
    assert 0.2 < sampler.acceptance_fraction[0] < 0.9
    assert np.all(sampler.swap_acceptance_fraction > 0.1)


def test_swaps_carry_the_cold_chain_into_a_mode_it_did_not_start_in():
    start = np.array([3.0])
    untempered, _ = run(two_modes, 1, [1.0], seed=2, max_steps=1500, start=start, iat_multiple=1e9)
    tempered, _ = run(
        two_modes, 1, geometric_betas(5, 1, max_temperature=200.0), seed=2, max_steps=1500, start=start,
        iat_multiple=1e9,
    )
    share_untempered = np.mean(untempered.backend.get_chain(discard=300, flat=True) < 0)
    share_tempered = np.mean(tempered.backend.get_chain(discard=300, flat=True) < 0)
    assert share_untempered == 0.0
    assert 0.3 < share_tempered < 0.7


def test_a_seeded_run_gives_the_same_chain_twice():
    first, _ = run(gaussian, 2, geometric_betas(3, 2), seed=7, max_steps=120, start=MEAN)
    second, _ = run(gaussian, 2, geometric_betas(3, 2), seed=7, max_steps=120, start=MEAN)
    other, _ = run(gaussian, 2, geometric_betas(3, 2), seed=8, max_steps=120, start=MEAN)
    np.testing.assert_array_equal(first.backend.get_chain(), second.backend.get_chain())
    np.testing.assert_array_equal(first.betas, second.betas)
    assert not np.array_equal(first.backend.get_chain(), other.backend.get_chain())


def test_the_step_cap_is_reported_as_not_converged():
    _, convergence = run(gaussian, 2, geometric_betas(2, 2), seed=3, max_steps=150, start=MEAN, check_interval=50)
    assert not convergence.converged and convergence.n_steps == 150 and len(convergence.iat_history) == 3


def test_every_temperature_is_evaluated_in_one_call_per_half_step():
    calls = []

    def counting(coords):
        calls.append(coords.shape[0])
        return gaussian(coords)

    run(counting, 2, geometric_betas(3, 2), seed=4, max_steps=10, start=MEAN)
    assert calls == [3 * 8] + [3 * 4] * 20  # the initial state, then two halves per step


def test_adaptive_ladder_keeps_the_ends_and_the_order():
    sampler, _ = run(gaussian, 2, geometric_betas(4, 2, max_temperature=50.0), seed=5, max_steps=300, start=MEAN)
    assert sampler.betas[0] == 1.0 and sampler.betas[-1] == pytest.approx(1 / 50.0)
    assert np.all(np.diff(sampler.betas) < 0)
    assert not np.allclose(sampler.betas, geometric_betas(4, 2, max_temperature=50.0))


def test_bad_set_up_is_refused():
    with pytest.raises(ValueError, match="need an even number of at least 2 · n_dim = 6"):
        ParallelTemperingSampler(gaussian, 4, 3)
    with pytest.raises(ValueError, match="need 1 first, strictly decreasing"):
        ParallelTemperingSampler(gaussian, 8, 2, betas=[0.5, 1.0])
    sampler = ParallelTemperingSampler(gaussian, 8, 2, betas=[1.0, 0.5])
    start = np.zeros((8, 2))
    start[5] = [20.0, 0.0]
    with pytest.raises(ValueError, match="initial walker 5 at temperature index 0 has zero posterior probability"):
        sampler.run(start, 10)
    with pytest.raises(ValueError, match=r"initial has shape \(3, 2\), expected \(8, 2\)"):
        sampler.run(np.zeros((3, 2)), 10)


def test_a_differential_evolution_mixture_samples_the_same_correlated_gaussian():
    import emcee

    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.StretchMove(), 0.2)]
    sampler = ParallelTemperingSampler(gaussian, 8, 2, betas=geometric_betas(3, 2), moves=moves, random_state=4)
    rng = np.random.default_rng(4)
    convergence = sampler.run(MEAN + 0.1 * rng.standard_normal((8, 2)), 5000)
    assert convergence.converged
    samples = sampler.backend.get_chain(discard=convergence.burn_in, thin=convergence.thin, flat=True)
    np.testing.assert_allclose(samples.mean(axis=0), MEAN, atol=0.15)
    np.testing.assert_allclose(np.cov(samples.T), COVARIANCE, atol=0.15)
    with pytest.raises(ValueError, match="positive weights"):
        ParallelTemperingSampler(gaussian, 8, 2, moves=[(emcee.moves.DEMove(), 0.0)]).run(np.zeros((8, 2)) + MEAN, 10)
    with pytest.raises(ValueError, match="DESnookerMove split the ensemble in more than two"):
        ParallelTemperingSampler(gaussian, 8, 2, moves=emcee.moves.DESnookerMove()).run(np.zeros((8, 2)) + MEAN, 10)
