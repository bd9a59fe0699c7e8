"""Point calibration: recovery of a synthetic truth, identifiability verdicts, exact covariance when linear."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_zone import NAMES, TRUTH, zone_windows

from service.calibration.lockstep import with_prefetched_rows
from service.calibration.metrics import long_run_variance_factor
from service.calibration.point import PointCalibrator
from service.calibration.problem import CalibrationProblem


@pytest.fixture(scope="module")
def zone_fit():
    (problem,) = zone_windows(1, seed=1)
    return problem, PointCalibrator(random_state=0).fit(problem)


def test_identifiable_parameters_are_recovered_within_5_percent(zone_fit):
    _, fit = zone_fit
    for name in ("UA_W_per_K", "C_J_per_K"):
        i = NAMES.index(name)
        assert fit.theta_[i] == pytest.approx(TRUTH[i], rel=0.05)
        assert fit.identifiability_[name].identified, fit.identifiability_[name].reasons
    # only the product η·P is determined by the data
    assert fit.theta_[2] * fit.theta_[3] == pytest.approx(TRUTH[2] * TRUTH[3], rel=0.05)


def test_the_unidentifiable_pair_is_flagged_with_its_partner(zone_fit):
    _, fit = zone_fit
    efficiency, power = fit.identifiability_["heater_efficiency"], fit.identifiability_["heater_power_W"]
    assert not efficiency.identified and not power.identified
    assert any(r.startswith("flat direction") and "moves with heater_power_W" in r for r in efficiency.reasons)
    assert any("correlated with heater_efficiency" in r for r in power.reasons)
    assert fit.correlation_[2, 3] < -0.95
    assert fit.singular_values_[-1] < 1e-3 * fit.singular_values_[0]


def test_residuals_and_prediction_are_reported_per_target(zone_fit):
    problem, fit = zone_fit
    for key in problem.target_keys:
        np.testing.assert_allclose(fit.residuals_[key], problem.observed[key] - fit.prediction_[key])
    weighted = np.concatenate([fit.residuals_[k] / problem.target_scales[k] for k in problem.target_keys])
    assert fit.cost_ == pytest.approx(0.5 * np.sum(weighted**2), rel=1e-9)
    # the model is right: residuals are the white sensor noise (σ = 0.1 K)
    assert np.std(fit.residuals_["zone_temperature"]) == pytest.approx(0.1, rel=0.15)


def linear_problem(simulate_log=None, n=40, default=None):
    t = np.linspace(0.0, 1.0, n)
    rng = np.random.default_rng(4)
    observed = 2.0 + 3.0 * t + 0.2 * rng.normal(size=n)

    def simulate(theta):
        if simulate_log is not None:
            simulate_log.append(theta.shape[0])
        return {"y": theta[:, :1] + theta[:, 1:2] * t}

    problem = CalibrationProblem(
        parameter_names=("intercept", "slope"), lower=np.array([-10.0, -10.0]), upper=np.array([10.0, 10.0]),
        simulate=simulate, observed={"y": observed}, target_scales={"y": 0.7}, default=default,
    )
    return problem, t, observed


def test_linear_model_gives_the_ordinary_least_squares_estimate_and_covariance():
    problem, t, y = linear_problem()
    fit = PointCalibrator(random_state=1).fit(problem)
    design = np.column_stack([np.ones_like(t), t])
    beta, residual_sum, *_ = np.linalg.lstsq(design, y, rcond=None)
    factor = long_run_variance_factor(y - design @ beta)  # white noise: near 1
    covariance = residual_sum[0] / (t.size - 2) * np.linalg.inv(design.T @ design) * factor  # σ²(XᵀX)⁻¹, n − p
    np.testing.assert_allclose(fit.theta_, beta, rtol=1e-6)
    np.testing.assert_allclose(fit.covariance_, covariance, rtol=1e-4)
    np.testing.assert_allclose(fit.standard_errors_, np.sqrt(np.diag(covariance)), rtol=1e-4)
    assert fit.correlation_[0, 1] == pytest.approx(covariance[0, 1] / np.sqrt(covariance[0, 0] * covariance[1, 1]), rel=1e-4)


def test_standard_errors_carry_each_targets_own_noise():
    """Two targets scaled alike with noises 25× apart, one parameter each: each standard error is its
    own target's (the exact per-target least-squares one), and over repeated noise the offsets from
    the truth in those standard errors are standard normal. One pooled variance would make the quiet
    target's parameter look 18× less certain than it is and the noisy one's 1.4× more."""
    t = np.linspace(0.0, 1.0, 60)
    noise = {"quiet": 0.02, "noisy": 0.5}
    truth = np.array([1.5, -0.8])

    def problem_for(rng):
        observed = {"quiet": truth[0] * t + noise["quiet"] * rng.normal(size=t.size),
                    "noisy": truth[1] * t + noise["noisy"] * rng.normal(size=t.size)}
        return CalibrationProblem(
            parameter_names=("a", "b"), lower=np.array([-5.0, -5.0]), upper=np.array([5.0, 5.0]),
            simulate=lambda theta: {"quiet": theta[:, :1] * t, "noisy": theta[:, 1:2] * t},
            observed=observed, target_scales={"quiet": 1.0, "noisy": 1.0}), observed

    rng = np.random.default_rng(11)
    problem, observed = problem_for(rng)
    fit = PointCalibrator(n_starts=1, n_candidates=4, random_state=0).fit(problem)
    dof_share = 1 - 2 / (2 * t.size)  # each target carries its share of the two parameters' degrees of freedom
    for j, key in enumerate(("quiet", "noisy")):
        slope = observed[key] @ t / (t @ t)
        variance = np.sum((observed[key] - slope * t) ** 2) / (t.size * dof_share)
        variance *= long_run_variance_factor(observed[key] - slope * t)
        assert fit.standard_errors_[j] == pytest.approx(np.sqrt(variance / (t @ t)), rel=1e-4)
    z = np.array([(f.theta_ - truth) / f.standard_errors_ for f in (
        PointCalibrator(n_starts=1, n_candidates=4, random_state=0).fit(problem_for(rng)[0]) for _ in range(150))])
    np.testing.assert_allclose(np.sqrt(np.mean(z**2, axis=0)), 1.0, atol=0.2)


def _level_fits(noise_draws, level=1.0):
    """(estimate, standard error) of a level fitted to ``level`` + each draw of ``noise_draws``."""
    fits = []
    for noise in noise_draws:
        n = noise.size
        problem = CalibrationProblem(
            parameter_names=("level",), lower=np.array([-20.0]), upper=np.array([20.0]),
            simulate=lambda theta, n=n: {"y": np.repeat(theta[:, :1], n, axis=1)},
            observed={"y": level + noise}, target_scales={"y": 1.0})
        fit = PointCalibrator(n_starts=1, n_candidates=2, random_state=0, check_jumps=False).fit(problem)
        fits.append((fit.theta_[0], fit.standard_errors_[0]))
    return np.array(fits)


def test_autocorrelated_residuals_count_as_fewer_observations():
    """A level measured through AR(1) noise (ρ = 0.9: a misfit that lasts about ten steps): over 300
    draws the truth lies within 1.96 standard errors in 84–98 % of them (95 % nominal; Newey–West
    with Bartlett weights runs short at this persistence, about 88 %); counted as white, the errors
    would be √19 ≈ 4.4× too small and the truth inside in about 35 %."""
    n, rho = 1000, 0.9
    rng = np.random.default_rng(5)
    draws = []
    for _ in range(300):
        noise = np.empty(n)
        noise[0] = rng.normal() / np.sqrt(1 - rho**2)
        for i in range(1, n):
            noise[i] = rho * noise[i - 1] + rng.normal()
        draws.append(0.1 * noise)
    fits = _level_fits(draws)
    inside = np.abs(fits[:, 0] - 1.0) <= 1.96 * fits[:, 1]
    assert 0.84 <= np.mean(inside) <= 0.98, np.mean(inside)


def test_a_misfit_that_oscillates_is_not_counted_as_a_slow_one():
    """A loop hunting with a 20-step period under white noise: ρ₁ ≈ 0.9, but the oscillation averages
    out of a level, whose estimates spread as the white noise alone makes them. Over 100 draws the
    standard errors are below those of residuals counted as white (3.6× the spread here; the
    Bartlett window's leakage leaves about 3×), where a lag-1 AR(1) count made them 15× the spread."""
    n = 1000
    rng = np.random.default_rng(6)
    steps = np.arange(n)
    draws = [np.sin(2 * np.pi * steps / 20 + rng.uniform(0, 2 * np.pi)) + 0.2 * rng.normal(size=n) for _ in range(100)]
    fits = _level_fits(draws)
    as_white = np.median([np.std(d) / np.sqrt(n) for d in draws])
    spread = np.std(fits[:, 0])
    assert spread <= np.median(fits[:, 1]) <= 0.9 * as_white, (np.median(fits[:, 1]), spread, as_white)


def test_jacobian_and_start_screening_are_one_simulate_call_each():
    calls: list[int] = []
    problem, *_ = linear_problem(calls, default=np.array([0.0, 0.0]))
    separate = PointCalibrator(n_starts=1, n_candidates=16, random_state=0, jacobian_with_residuals=False).fit(problem)
    assert calls[0] == 17  # 16 Latin-hypercube candidates + the default, one call
    assert set(calls[1:-1]) == {1, 3}  # residuals (1 member) and Jacobians (p + 1 = 3 members)
    assert calls[-1] == 4  # the jump check: ±2 SE in each identified parameter, one call
    assert separate.n_simulate_calls_ == len(calls) and separate.n_simulated_members_ == sum(calls)
    n_separate = len(calls)
    calls.clear()
    fused = PointCalibrator(n_starts=1, n_candidates=16, random_state=0).fit(problem)
    assert calls[0] == 17 and set(calls[1:-1]) == {3}  # every trial point simulated with its Jacobian
    assert len(calls) < n_separate  # an accepted step is one call, and the final point is not simulated again
    np.testing.assert_array_equal(fused.theta_, separate.theta_)
    np.testing.assert_array_equal(fused.covariance_, separate.covariance_)


def test_starts_fitted_in_lockstep_share_simulate_calls_and_find_what_they_find_alone():
    """Three starts of a nonlinear fit, each start's calls gathered into one simulate call while
    all run (3 × (p + 1) members), end where each ends alone (a problem that is not vectorised
    fits its starts one after another), in fewer calls."""
    t = np.linspace(0.0, 5.0, 60)
    observed = 2.0 * np.exp(-0.7 * t) + 0.5 + 0.01 * np.random.default_rng(3).normal(size=t.size)

    def problem(calls, vectorised):
        def simulate(theta):
            calls.append(theta.shape[0])
            return {"y": theta[:, :1] * np.exp(-theta[:, 1:2] * t) + theta[:, 2:3]}
        return CalibrationProblem(
            parameter_names=("amplitude", "rate", "floor"), lower=np.array([0.0, 0.01, -2.0]),
            upper=np.array([5.0, 5.0, 2.0]), simulate=simulate, observed={"y": observed},
            target_scales={"y": 0.01}, vectorised_simulate=vectorised)

    lockstep_calls, alone_calls = [], []
    settings = dict(n_starts=3, n_candidates=12, random_state=2, jacobian_with_residuals=True)
    together = PointCalibrator(**settings).fit(problem(lockstep_calls, True))
    alone = PointCalibrator(**settings).fit(problem(alone_calls, False))
    np.testing.assert_allclose(together.start_costs_, alone.start_costs_, rtol=1e-9)
    np.testing.assert_allclose(together.theta_, alone.theta_, rtol=1e-9)
    assert max(lockstep_calls[1:-1]) == 3 * 4 and max(alone_calls[1:-1]) == 4
    assert len(lockstep_calls) < 0.6 * len(alone_calls)


def test_a_seeded_fit_is_reproducible():
    (problem,) = zone_windows(1, steps_per_day=48, seed=2)
    first = PointCalibrator(n_starts=2, random_state=3).fit(problem)
    second = PointCalibrator(n_starts=2, random_state=3).fit(problem)
    np.testing.assert_array_equal(first.theta_, second.theta_)


def test_parameters_against_a_bound_or_too_uncertain_are_flagged():
    problem, *_ = linear_problem()
    tight = CalibrationProblem(
        parameter_names=problem.parameter_names, lower=np.array([-10.0, 2.95]), upper=np.array([10.0, 10.0]),
        simulate=problem.simulate, observed=problem.observed, target_scales=problem.target_scales,
    )
    fit = PointCalibrator(random_state=0).fit(tight)
    assert any("crosses the prior bounds" in r for r in fit.identifiability_["slope"].reasons)


def test_invalid_settings_and_too_little_data_are_refused():
    problem, *_ = linear_problem(n=2)
    with pytest.raises(ValueError, match=r"2 measured values cannot determine 2 parameters \(need n > p\)"):
        PointCalibrator(random_state=0).fit(problem)
    with pytest.raises(ValueError, match="need 1 ≤ n_starts ≤ n_candidates"):
        PointCalibrator(n_starts=5, n_candidates=4).fit(problem)


def test_a_cost_that_jumps_within_two_standard_errors_is_not_called_identified():
    """The linear model, plus a step of 0.5·t in the output once the slope exceeds 3.05: the fit
    lands below the step (slope ≈ 3.0, SE ≈ 0.1) where the Jacobian is that of the linear model, so
    its standard error alone would call the slope identified; moved by +2 SE the cost jumps."""
    problem, t, _ = linear_problem()
    smooth = PointCalibrator(random_state=1).fit(problem)
    assert all(v.identified for v in smooth.identifiability_.values())
    linear_simulate = problem.simulate

    def simulate(theta):
        return {"y": linear_simulate(theta)["y"] + 0.5 * (theta[:, 1:2] > 3.05) * t}

    from dataclasses import replace
    jumping = PointCalibrator(random_state=1).fit(replace(problem, simulate=simulate))
    assert jumping.theta_[1] < 3.05 < jumping.theta_[1] + 2 * jumping.standard_errors_[1]
    slope = jumping.identifiability_["slope"]
    assert not slope.identified and slope.reasons[0].startswith("the cost jumps at the estimate")
    assert jumping.identifiability_["intercept"].identified  # ±2 SE in the intercept alone crosses no step


def test_a_fit_stopped_at_its_evaluation_limit_says_so_and_can_run_on_from_where_it_stopped():
    """The zone (nonlinear, 5 parameters) with 3 evaluations a start: not converged; continued three
    times it gets closer to the converged cost, and an unlimited fit says it converged."""
    (problem,) = zone_windows(1, seed=1)
    stopped = PointCalibrator(n_starts=1, n_candidates=4, random_state=0, max_nfev=3).fit(problem)
    continued = PointCalibrator(n_starts=1, n_candidates=4, random_state=0, max_nfev=3, continuations=3).fit(problem)
    full = PointCalibrator(n_starts=1, n_candidates=4, random_state=0).fit(problem)
    assert not stopped.converged_ and full.converged_
    assert full.cost_ <= continued.cost_ < stopped.cost_


def test_a_looser_cost_tolerance_stops_sooner_at_about_the_same_cost():
    """The zone (nonlinear, 5 parameters): stopping where a step lowers the cost by less than 1e-5 of
    it (the diagnosis's refits) takes fewer simulate calls than SciPy's 1e-8, converges, and ends
    within that share of the tight fit's cost; the refits' calibrator carries that tolerance."""
    from service.diagnosis.refits import REFIT_COST_TOLERANCE, refit_calibrator

    for seed in (2, 3):  # draws whose tight fit takes its last steps for a few parts per million
        (problem,) = zone_windows(1, seed=seed)
        tight = PointCalibrator(n_starts=1, n_candidates=4, random_state=0).fit(problem)
        loose = PointCalibrator(n_starts=1, n_candidates=4, random_state=0, cost_tolerance=1e-5).fit(problem)
        assert loose.converged_ and loose.n_simulate_calls_ < tight.n_simulate_calls_
        assert tight.cost_ <= loose.cost_ <= tight.cost_ * (1 + 1e-5)
    assert refit_calibrator(0, 30).cost_tolerance == REFIT_COST_TOLERANCE == 1e-5


def test_prefetched_rows_are_served_without_a_call_and_only_missing_rows_are_simulated():
    """Two ensembles simulated ahead in one call; a later call asking for some of their rows (one
    moved by a few ulps, as a trip through the unit cube moves it) and one new row simulates the new
    row alone, and every row is what a direct call gives."""
    t = np.linspace(0.0, 1.0, 20)
    calls = []

    def simulate(theta):
        calls.append(theta.shape[0])
        return {"y": theta[:, :1] * t + theta[:, 1:2] * t**2}

    problem = CalibrationProblem(parameter_names=("a", "b"), lower=np.array([0.0, -1.0]), upper=np.array([3.0, 1.0]),
                                 simulate=simulate, observed={"y": t})
    first, second = np.array([[1.0, 0.2], [2.0, -0.5]]), np.array([[0.3, 0.9]])
    ahead = with_prefetched_rows(problem, first, second)
    assert calls == [3]
    trip = problem.from_unit(problem.to_unit(second))
    asked = np.vstack([trip, first[1:], [[2.5, 0.1]]])
    served = ahead.run(asked)
    assert calls == [3, 1]
    np.testing.assert_allclose(served["y"], simulate(asked)["y"], rtol=1e-12)
    ahead.run(first)
    assert calls == [3, 1, 3]
