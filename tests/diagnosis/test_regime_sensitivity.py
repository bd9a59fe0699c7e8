"""Morris per regime on analytic functions whose sensitivities per regime are known."""

import numpy as np
import pytest

from service.calibration.regime_sensitivity import morris_by_regime, successive_calibration_plan

#: 100 steps: regime 0 (40 steps), 1 (30), 2 (30); x is a known driving signal.
LABELS = np.repeat([0, 1, 2], [40, 30, 30])
X_SIGNAL = np.linspace(1.0, 2.0, 100)
PROBLEM = {"num_vars": 4, "names": ["a", "b", "c", "d"], "bounds": [[0.0, 1.0], [0.0, 2.0], [0.0, 1.0], [5.0, 6.0]]}


class CountingModel:
    """y(t) = a·x(t) in regime 1, (b + 0.5·c)·x(t) in regime 2, 0 in regime 0; d does nothing.
    Vectorised over the ensemble; counts its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        self.calls += 1
        a, b, c, _ = theta.T[:, :, None]
        return np.where(LABELS == 1, a * X_SIGNAL, 0.0) + np.where(LABELS == 2, (b + 0.5 * c) * X_SIGNAL, 0.0)


def test_mean_output_mu_star_matches_the_linear_elementary_effects():
    model = CountingModel()
    result = morris_by_regime(PROBLEM, model, LABELS, n_trajectories=10, seed=3)
    assert model.calls == 1  # one ensemble run for all trajectories
    assert result.regimes == [0, 1, 2] and result.n_steps == [40, 30, 30]
    # Linear measure Y = k·θ: every elementary effect is k·(upper − lower): μ* = |k|·(upper − lower), σ = 0.
    mean_x1, mean_x2 = X_SIGNAL[LABELS == 1].mean(), X_SIGNAL[LABELS == 2].mean()
    expected = np.array([[0, 0, 0, 0], [mean_x1 * 1.0, 0, 0, 0], [0, mean_x2 * 2.0, 0.5 * mean_x2 * 1.0, 0]])
    np.testing.assert_allclose(result.mu_star, expected, atol=1e-12)
    np.testing.assert_allclose(result.sigma, 0.0, atol=1e-12)
    assert result.dominant_parameters(1) == ["a"]
    assert result.dominant_parameters(2) == ["b", "c"]  # shares 0.8 and 0.2
    assert result.dominant_parameters(2, threshold=0.5) == ["b"]
    assert result.dominant_parameters(0) == []
    np.testing.assert_allclose(result.normalised_mu_star()[2], [0.0, 0.8, 0.2, 0.0])


def test_rmse_measure_sees_each_parameter_only_in_its_regime():
    observed = np.where(LABELS == 1, 0.3 * X_SIGNAL, 0.0) + np.where(LABELS == 2, 1.2 * X_SIGNAL, 0.0)
    observed[[5, 45, 75]] = np.nan  # unmeasured steps are left out of the measure
    result = morris_by_regime(PROBLEM, CountingModel(), LABELS, observed, n_trajectories=12, seed=0)
    assert result.measure == "rmse" and result.n_steps == [39, 29, 29]
    assert result.mu_star[1, 0] > 0.1 and result.mu_star[1, 1:] == pytest.approx([0, 0, 0], abs=1e-12)
    assert result.mu_star[2, 0] == pytest.approx(0, abs=1e-12) and result.mu_star[2, 1] > result.mu_star[2, 2] > 0
    assert result.mu_star[0] == pytest.approx([0, 0, 0, 0], abs=1e-12)
    assert "regime 2 (n=29)" in result.table()


def test_successive_plan_assigns_each_parameter_to_its_regime_and_orders_by_count():
    result = morris_by_regime(PROBLEM, CountingModel(), LABELS, n_trajectories=10, seed=3)
    # b and c belong to regime 2 (two parameters: first), a to regime 1; d moves nothing and is left out.
    assert successive_calibration_plan(result) == [(2, ["b", "c"]), (1, ["a"])]
    # With c below the minimum share it is dropped, and the tie (one parameter each) goes to the larger share.
    assert successive_calibration_plan(result, min_share=0.25) == [(1, ["a"]), (2, ["b"])]


def test_a_parameter_that_matters_in_two_regimes_goes_where_its_share_is_highest():
    problem = {"num_vars": 2, "names": ["a", "b"], "bounds": [[0.0, 1.0], [0.0, 1.0]]}

    def model(theta):
        a, b = theta.T[:, :, None]
        regime_1 = np.where(LABELS == 1, (a + b) * X_SIGNAL, 0.0)
        return regime_1 + np.where(LABELS == 2, (3 * a + 9 * b) * X_SIGNAL, 0.0)

    result = morris_by_regime(problem, model, LABELS, n_trajectories=8, seed=1)
    # a's raw μ* is larger in regime 2 (3·1.85 vs 1.55) but its share is larger in regime 1 (1/2 vs 1/4).
    assert result.mu_star[2, 0] > result.mu_star[1, 0]
    np.testing.assert_allclose(result.normalised_mu_star()[1:], [[0.5, 0.5], [0.25, 0.75]])
    # One parameter each: the tie goes to the larger share, b's 3/4 in regime 2.
    assert successive_calibration_plan(result) == [(2, ["b"]), (1, ["a"])]


def test_bad_problem_and_bad_simulation_are_refused():
    with pytest.raises(ValueError, match="lacks"):
        morris_by_regime({"names": ["a"], "bounds": [[0, 1]]}, CountingModel(), LABELS)
    with pytest.raises(ValueError, match="'d' has bounds"):
        morris_by_regime({**PROBLEM, "bounds": [[0, 1], [0, 1], [0, 1], [2, 2]]}, CountingModel(), LABELS)
    with pytest.raises(ValueError, match=r"simulate returned shape \(\d+, 99\)"):
        morris_by_regime(PROBLEM, lambda theta: CountingModel()(theta)[:, :99], LABELS)
    with pytest.raises(ValueError, match="non-finite values in regime 1"):
        morris_by_regime(PROBLEM, lambda theta: np.where(LABELS == 1, np.nan, 0.0) + 0 * theta[:, :1], LABELS)
    with pytest.raises(KeyError, match="regime 7"):
        morris_by_regime(PROBLEM, CountingModel(), LABELS, n_trajectories=4, seed=0).dominant_parameters(7)


def test_calibration_measure_is_the_weighted_rms_residual_over_the_stacked_targets():
    from service.calibration.problem import CalibrationProblem
    from service.calibration.regime_sensitivity import calibration_morris_by_regime

    model = CountingModel()
    observed = np.where(LABELS == 1, 0.3 * X_SIGNAL, 0.0) + np.where(LABELS == 2, 1.2 * X_SIGNAL, 0.0)
    bounds = np.array(PROBLEM["bounds"])

    def problem(targets):
        return CalibrationProblem(
            parameter_names=tuple(PROBLEM["names"]), lower=bounds[:, 0], upper=bounds[:, 1],
            simulate=lambda theta: {k: model(theta) for k in targets}, observed={k: observed for k in targets},
            target_scales={k: 0.5 for k in targets})

    single = morris_by_regime(PROBLEM, CountingModel(), LABELS, observed, n_trajectories=6, seed=2)
    weighted = calibration_morris_by_regime(problem(["y"]), LABELS, n_trajectories=6, seed=2)
    # Dividing every residual by the scale 0.5 doubles every elementary effect of the RMS residual …
    np.testing.assert_allclose(weighted.mu_star, single.mu_star / 0.5, atol=1e-12)
    # … and a second, identical target leaves the RMS over both (and so μ*) unchanged, over twice the values.
    twice = calibration_morris_by_regime(problem(["y", "z"]), LABELS, n_trajectories=6, seed=2)
    np.testing.assert_allclose(twice.mu_star, weighted.mu_star, atol=1e-12)
    assert twice.n_steps == [2 * n for n in weighted.n_steps]
    ranking = twice.ranking(2, top=2)
    assert [row["parameter"] for row in ranking] == ["b", "c"] and ranking[0]["mu_star"] > ranking[1]["mu_star"]
    assert sum(row["share"] for row in twice.ranking(2)) == pytest.approx(1.0)
