"""Which physical effect is missing: score test at the null, refit, out-of-sample check, ranking.

For one candidate (an effect signature at one building node): the **score test** at the null (the
RSS the bounded Gauss–Newton step on the effect's directions would remove beyond the base's, over
σ̂² = RSS/(n − p), scaled by n_eff/n with n_eff = n·(1 − ρ₁)/(1 + ρ₁); ~χ²_k), the **refit** compared
by ΔBIC = n_eff·ln(RSS₁/RSS₀) + k·ln(n_eff), and the share of the test-window weighted squared error
it removes **out of sample**. Significant: ΔBIC < ``bic_threshold`` and at least
``min_test_improvement`` removed; ranked by the share removed (two decimals), then fewer parameters,
then ΔBIC. The method in full: ``docs/diagnosis.md``, "What is missing".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear
from scipy.stats import chi2

from service.calibration.problem import CalibrationProblem

__all__ = [
    "ScoreTest", "EffectEvidence", "score_test", "effective_sample_fraction", "rank_evidence", "delta_bic",
    "weighted_test_error",
]


@dataclass(frozen=True)
class ScoreTest:
    """Score test of a candidate effect at its null value."""

    statistic: float
    loglik_gain: float
    p_value: float
    active_parameters: tuple[str, ...]


@dataclass
class EffectEvidence:
    """Everything known about one (effect, node) candidate; filled by the diagnosis."""

    effect: str
    effect_iri: str
    node: str
    label: str
    parameter_names: tuple[str, ...]
    score: ScoreTest
    delta_bic: float = float("nan")
    estimates: dict[str, float] = field(default_factory=dict)
    standard_errors: dict[str, float] = field(default_factory=dict)
    rmse_before: dict[str, float] = field(default_factory=dict)
    rmse_after: dict[str, float] = field(default_factory=dict)
    test_improvement: float = float("nan")
    residual_correlation: tuple[str, float] | None = None
    significant: bool = False
    explanation: str = ""

    def to_dict(self) -> dict:
        return {
            "effect": self.effect_iri, "effect_id": self.effect, "target": self.node, "label": self.label,
            "score": self.score.statistic, "loglik_gain": self.score.loglik_gain, "p_value": self.score.p_value,
            "delta_bic": self.delta_bic, "significant": self.significant,
            "estimates": self.estimates, "standard_errors": self.standard_errors,
            "test_improvement": self.test_improvement, "rmse_before": self.rmse_before,
            "rmse_after": self.rmse_after, "explanation": self.explanation,
        }


def effective_sample_fraction(residuals: np.ndarray) -> float:
    """n_eff / n = (1 − ρ₁)/(1 + ρ₁) from the lag-1 autocorrelation ρ₁ of ``residuals`` (NaN-free,
    one series or a concatenation), clipped to [1/n, 1]."""
    r = np.asarray(residuals, dtype=float)
    r = r - r.mean()
    denominator = float(np.dot(r, r))
    if r.size < 3 or denominator == 0.0:
        return 1.0
    rho = float(np.dot(r[1:], r[:-1]) / denominator)
    return float(np.clip((1.0 - rho) / (1.0 + rho), 1.0 / r.size, 1.0))


def score_test(
    problem: CalibrationProblem,
    theta_null: np.ndarray,
    effect_columns: Sequence[int],
    *,
    relative_step: float = 1e-3,
    sample_fraction: float | None = None,
) -> ScoreTest:
    """Score test for the parameters in ``effect_columns`` of ``problem`` at ``theta_null``.

    :param theta_null: θ with the base parameters at their estimate and the effect's at the null.
    :param effect_columns: columns of θ that belong to the effect.
    :param relative_step: forward-difference step as a share of each parameter's prior width
        (taken backwards when the parameter sits at its upper bound).
    :param sample_fraction: n_eff/n; computed from the base residuals when None.
    """
    theta_null = np.asarray(theta_null, dtype=float)
    n_par = theta_null.size
    width = problem.upper - problem.lower
    steps = relative_step * width
    steps = np.where(theta_null + steps > problem.upper, -steps, steps)
    ensemble = np.repeat(theta_null[None, :], n_par + 1, axis=0)
    ensemble[np.arange(1, n_par + 1), np.arange(n_par)] += steps
    residuals = problem.weighted_residuals(problem.run(ensemble))
    base_residual = residuals[0]
    jacobian = (residuals[1:] - base_residual).T / steps
    n = base_residual.size
    fraction = effective_sample_fraction(base_residual) if sample_fraction is None else sample_fraction
    effect = [int(c) for c in effect_columns]
    base = [c for c in range(n_par) if c not in effect]
    sigma2 = float(np.dot(base_residual, base_residual)) / max(n - len(base), 1)
    # the Gauss–Newton step solves J δ ≈ −r (residual r = y − ŷ decreases along −J^+ r); with the base
    # free, what the effect adds is the bounded least squares of −r's part outside the base's span on
    # the effect columns' parts outside it
    def outside_base(columns: np.ndarray) -> np.ndarray:
        if not base:
            return columns
        coefficients, *_ = np.linalg.lstsq(jacobian[:, base], columns, rcond=1e-10)
        return columns - jacobian[:, base] @ coefficients

    target = outside_base(-base_residual)
    directions = outside_base(jacobian[:, effect])
    step = lsq_linear(directions, target, bounds=(problem.lower[effect] - theta_null[effect],
                                                  problem.upper[effect] - theta_null[effect])).x
    left = directions @ step - target
    gain_rss = float(np.dot(target, target) - np.dot(left, left))
    statistic = max(gain_rss, 0.0) / sigma2 * fraction
    moved = [c for c, d in zip(effect, step) if abs(d) > 1e-9 * width[c] and np.any(jacobian[:, c] != 0.0)]
    k = max(len(moved), 1)
    on_bound = any(np.isclose(theta_null[c], problem.lower[c]) or np.isclose(theta_null[c], problem.upper[c]) for c in moved)
    p_value = (0.5 if on_bound else 1.0) * float(chi2.sf(statistic, k)) if statistic > 0 else 1.0
    return ScoreTest(
        statistic=float(statistic), loglik_gain=float(statistic / 2.0), p_value=p_value,
        active_parameters=tuple(problem.parameter_names[c] for c in moved),
    )


def delta_bic(rss_base: float, rss_effect: float, n_effective: float, n_extra: int) -> float:
    """ΔBIC = n_eff·ln(RSS₁/RSS₀) + k·ln(n_eff); negative favours the effect."""
    return float(n_effective * np.log(max(rss_effect, 1e-300) / max(rss_base, 1e-300)) + n_extra * np.log(n_effective))


def rank_evidence(
    evidence: Sequence[EffectEvidence], *, bic_threshold: float = -10.0, min_test_improvement: float = 0.2
) -> list[EffectEvidence]:
    """Mark significant candidates and order them best first (see the module docstring)."""
    for item in evidence:
        item.significant = bool(
            np.isfinite(item.delta_bic) and item.delta_bic < bic_threshold
            and np.isfinite(item.test_improvement) and item.test_improvement >= min_test_improvement
        )

    def key(item: EffectEvidence):
        improvement = item.test_improvement if np.isfinite(item.test_improvement) else -np.inf
        bic = item.delta_bic if np.isfinite(item.delta_bic) else np.inf
        return (not item.significant, -round(improvement, 2), len(item.parameter_names), bic, item.effect, item.node)

    return sorted(evidence, key=key)


def weighted_test_error(
    observed: Mapping[str, np.ndarray], predicted: Mapping[str, np.ndarray], scales: Mapping[str, float]
) -> float:
    """Σ_targets mean(((y − ŷ)/s)²) over the measured points: the error the ranking compares."""
    total = 0.0
    for key, values in observed.items():
        mask = np.isfinite(values)
        if mask.any():
            total += float(np.mean(((values[mask] - predicted[key][mask]) / scales[key]) ** 2))
    return total

