"""Score test, ΔBIC and ranking on analytic problems whose answer is known."""

import numpy as np
import pytest

from service.calibration.problem import CalibrationProblem
from service.diagnosis.ranking import (
    EffectEvidence,
    ScoreTest,
    delta_bic,
    effective_sample_fraction,
    rank_evidence,
    score_test,
)

T = np.linspace(0.0, 10.0, 400)
X = np.sin(T)
Z = np.where(T > 5.0, 1.0, 0.0)  # the effect's signal: a step the base model cannot make


def _problem(true_b: float, lower_b: float = 0.0, seed: int = 0) -> CalibrationProblem:
    rng = np.random.default_rng(seed)
    observed = 2.0 * X + true_b * Z + rng.normal(0.0, 0.05, T.size)

    def simulate(theta):
        return {"y": theta[:, :1] * X + theta[:, 1:2] * Z}

    return CalibrationProblem(
        parameter_names=("a", "b"), lower=np.array([0.0, lower_b]), upper=np.array([5.0, 2.0]),
        simulate=simulate, observed={"y": observed}, target_scales={"y": 0.05},
    )


def _base_estimate(problem):
    y = problem.observed["y"]
    return float(np.dot(X, y) / np.dot(X, X))


def test_score_test_detects_a_present_effect_and_predicts_the_likelihood_gain():
    problem = _problem(true_b=0.3)
    theta_null = np.array([_base_estimate(problem), 0.0])
    result = score_test(problem, theta_null, [1], sample_fraction=1.0)
    # the exact gain of adding b at the optimum: RSS0 − RSS1 of a linear least-squares problem
    y = problem.observed["y"] / 0.05
    design = np.column_stack([X, Z]) / 0.05
    rss0 = np.sum((y - X / 0.05 * theta_null[0]) ** 2)
    rss1 = np.sum((y - design @ np.linalg.lstsq(design, y, rcond=None)[0]) ** 2)
    sigma2 = rss0 / (T.size - 1)
    assert result.statistic == pytest.approx((rss0 - rss1) / sigma2, rel=1e-3)
    assert result.p_value < 1e-10
    assert result.active_parameters == ("b",)


def test_score_test_is_quiet_without_the_effect():
    p_values = []
    for seed in range(20):
        problem = _problem(true_b=0.0, lower_b=-2.0, seed=seed)
        result = score_test(problem, np.array([_base_estimate(problem), 0.0]), [1], sample_fraction=1.0)
        p_values.append(result.p_value)
    # a null in the interior: P(χ²₁ > S), as often below 0.01 as chance has it
    assert np.mean(np.array(p_values) < 0.01) <= 0.1


def test_an_effect_whose_step_overshoots_its_far_bound_counts_at_the_bound():
    """The demo's fan motor heat: the Gauss–Newton step from f = 0 went to 1.10 of at most 1. Held at
    its null for leaving its bounds, it scored 0 (p = 1) beside a ΔBIC of −7,835; at the bound it
    explains what a step of 2 there explains."""
    problem = _problem(true_b=3.0)  # b at most 2
    theta_null = np.array([_base_estimate(problem), 0.0])
    result = score_test(problem, theta_null, [1], sample_fraction=1.0)
    y = problem.observed["y"] / 0.05
    rss0 = np.sum((y - X / 0.05 * theta_null[0]) ** 2)
    a_at_b2 = np.dot(X, y - 2.0 * Z / 0.05) / np.dot(X, X) * 0.05  # the base refitted with b at its bound
    rss_bound = np.sum((y - (a_at_b2 * X + 2.0 * Z) / 0.05) ** 2)
    assert result.statistic == pytest.approx((rss0 - rss_bound) / (rss0 / (T.size - 1)), rel=1e-3)
    assert result.active_parameters == ("b",) and result.p_value < 1e-10


def test_an_effect_the_bounds_forbid_scores_zero():
    problem = _problem(true_b=-0.3, lower_b=0.0)
    result = score_test(problem, np.array([_base_estimate(problem), 0.0]), [1], sample_fraction=1.0)
    assert result.statistic == 0.0 and result.p_value == 1.0 and result.active_parameters == ()


def test_effective_sample_fraction_of_white_and_autocorrelated_noise():
    rng = np.random.default_rng(1)
    white = rng.normal(size=20_000)
    assert effective_sample_fraction(white) == pytest.approx(1.0, abs=0.03)
    ar = np.zeros(20_000)
    for i in range(1, ar.size):
        ar[i] = 0.9 * ar[i - 1] + white[i]
    assert effective_sample_fraction(ar) == pytest.approx(0.1 / 1.9, rel=0.1)


def test_delta_bic_sign_and_penalty():
    assert delta_bic(100.0, 50.0, 1000, 1) < 0
    assert delta_bic(100.0, 100.0, 1000, 1) == pytest.approx(np.log(1000))


def _evidence(effect, improvement, bic, n_par):
    return EffectEvidence(
        effect=effect, effect_iri=effect, node="n", label=effect,
        parameter_names=tuple(f"p{i}" for i in range(n_par)), score=ScoreTest(1.0, 0.5, 0.1, ()),
        delta_bic=bic, test_improvement=improvement,
    )


def test_ranking_prefers_significant_then_larger_improvement_then_fewer_parameters():
    stuck = _evidence("ValveStuck", 0.904, -520.0, 2)
    leak = _evidence("ValveLeakage", 0.901, -515.0, 1)
    offset = _evidence("SensorOffset", 0.95, -3.0, 1)  # not significant by BIC
    weak = _evidence("SensorLag", 0.4, -40.0, 1)
    ranked = rank_evidence([stuck, offset, weak, leak])
    assert [e.effect for e in ranked] == ["ValveLeakage", "ValveStuck", "SensorLag", "SensorOffset"]
    assert [e.significant for e in ranked] == [True, True, True, False]


def test_an_estimate_at_a_bound_of_its_prior_is_flagged_in_the_explanation():
    from service.components.component import Parameter
    from service.diagnosis.candidates import _bound_note

    offset = Parameter("offset", "K", 0.0, -5.0, 5.0, "sensor offset", null=0.0)
    assert _bound_note(4.99999999961, offset) == " (at its upper bound 5)"
    assert _bound_note(-5.0, offset) == " (at its lower bound -5)"
    assert _bound_note(4.9, offset) == ""


def test_an_estimate_the_data_leave_anywhere_in_its_prior_is_called_not_identified():
    from service.components.component import Parameter
    from service.diagnosis.candidates import _estimate_text

    leak = Parameter("leakage_fraction", "1", 0.0, 0.0, 0.3, "leakage", null=0.0)
    assert _estimate_text("leakage_fraction", 0.21, 1.3e8, leak) == \
        "leakage_fraction = 0.21, not identified (the data leave it anywhere in [0, 0.3])"
    assert _estimate_text("leakage_fraction", 0.21, float("inf"), leak).endswith("[0, 0.3])")
    assert _estimate_text("leakage_fraction", 0.21, 0.02, leak) == "leakage_fraction = 0.21 ± 0.02"
    assert _estimate_text("leakage_fraction", 0.3, 0.02, leak) == "leakage_fraction = 0.3 ± 0.02 (at its upper bound 0.3)"
