"""Which physical effect is missing: score test at the null, refit, out-of-sample check, ranking.

For one candidate (an effect signature at one building node): the **score test** at the null (the
RSS the bounded Gauss–Newton step on the effect's directions would remove beyond the base's, each
target over its own σ̂ₖ² and scaled by its n_eff,ₖ/nₖ = (1 − ρ₁)/(1 + ρ₁); ~χ̄²), the **refit**
compared by ΔBIC = Σₖ n_eff,ₖ·ln(RSS₁,ₖ/RSS₀,ₖ) + k·ln(Σ n_eff), and the share of the test-window
weighted squared error it removes **out of sample**. Significant: ΔBIC < ``bic_threshold`` and at least
``min_test_improvement`` removed; ranked significant first, then the plausible before those demoted
(an effect fitted only at a bound that is not its null), then by the share removed (two decimals),
ΔBIC (which already charges each extra parameter ln Σn_eff), fewer parameters. The method in full:
``docs/diagnosis.md``, "What is missing".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear
from scipy.stats import binom, chi2

from service.calibration.metrics import effective_sample_fraction
from service.calibration.problem import CalibrationProblem
from service.model.assembled_model import AssembledModel

#: The share of the evaluation half's weighted squared error an effect must remove to be significant
#: (and that it must remove at a sensor for the failure to be located there).
MIN_TEST_IMPROVEMENT = 0.2
#: ΔBIC below which a candidate's in-sample evidence counts ("strong" on Kass & Raftery's scale).
BIC_THRESHOLD = -10.0

__all__ = [
    "MIN_TEST_IMPROVEMENT", "BIC_THRESHOLD", "ScoreTest", "EffectEvidence", "score_test", "score_ensemble",
    "rank_evidence", "delta_bic",
    "weighted_test_error", "step_errors", "residual_step_errors",
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
    freed_parameters: int = 0  # counted in ΔBIC: the effect's, and its host's when fitted with it
    estimates: dict[str, float] = field(default_factory=dict)
    standard_errors: dict[str, float] = field(default_factory=dict)
    rmse_before: dict[str, float] = field(default_factory=dict)
    rmse_after: dict[str, float] = field(default_factory=dict)
    test_improvement: float = float("nan")
    significant: bool = False
    explanation: str = ""
    demoted: str = ""  # why the ranking puts it below the plausible effects (empty: it does not)
    implausible: bool = False  # demoted for its physics (a fit only at a bound, no heat source), not its refit
    appears_in_test_window: bool = False  # fitted as a fault appearing there (absent from the training window)
    # for telling look-alikes apart (service.diagnosis.separation), not part of the report: θ of the
    # fit kept (all estimated parameters), each evaluation step's share of the error after it, the model
    theta: np.ndarray | None = field(default=None, repr=False)
    evaluation_step_errors: np.ndarray | None = field(default=None, repr=False)
    fit_step_errors: np.ndarray | None = field(default=None, repr=False)  # the same over the fit windows
    model: AssembledModel | None = field(default=None, repr=False)

    def error_removed_at(self, node: str) -> float:
        """The share of ``node``'s squared error on the evaluation half the effect removes,
        1 − RMSE_after² / RMSE_before² (NaN where the sensor was not compared)."""
        before, after = self.rmse_before.get(node, np.nan), self.rmse_after.get(node, np.nan)
        return float(1.0 - (after / before) ** 2) if np.isfinite(before) and before > 0 else float("nan")

    def to_dict(self) -> dict:
        return {
            "effect": self.effect_iri, "effect_id": self.effect, "target": self.node, "label": self.label,
            "score": self.score.statistic, "loglik_gain": self.score.loglik_gain, "p_value": self.score.p_value,
            "delta_bic": self.delta_bic,
            "freed_parameters": self.freed_parameters, "significant": self.significant,
            "estimates": self.estimates, "standard_errors": self.standard_errors,
            "test_improvement": self.test_improvement, "rmse_before": self.rmse_before,
            "rmse_after": self.rmse_after, "explanation": self.explanation, "demoted": self.demoted,
            "appears_in_test_window": self.appears_in_test_window,
        }


def target_rows(problem: CalibrationProblem) -> np.ndarray:
    """For each value of :meth:`CalibrationProblem.weighted_residuals`, the index of its target."""
    counts = [int(mask.sum()) for mask in problem.masks.values()]
    return np.repeat(np.arange(len(counts)), counts)


def per_target_rss(residuals: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Σ r² per target of one weighted residual vector (``rows`` from :func:`target_rows`)."""
    return np.bincount(rows, weights=np.asarray(residuals, dtype=float) ** 2, minlength=int(rows.max(initial=-1)) + 1)


def bounded_null_p_value(statistic: float, interior: int, on_bound: int) -> float:
    """P(S > ``statistic``) under the χ̄² mixture of a null with ``interior`` parameters inside their
    range and ``on_bound`` at a bound (independent directions): Σⱼ C(m, j)/2ᵐ · P(χ²_{q+j} > S), χ²₀
    a point mass at 0. One parameter on its bound: half of P(χ²₁ > S)."""
    if statistic <= 0 or interior + on_bound == 0:
        return 1.0
    weights = binom.pmf(np.arange(on_bound + 1), on_bound, 0.5)
    return float(sum(w * chi2.sf(statistic, interior + j) for j, w in enumerate(weights) if interior + j > 0))


def score_ensemble(problem: CalibrationProblem, theta_null: np.ndarray, relative_step: float = 1e-3) -> np.ndarray:
    """The members :func:`score_test` simulates: ``theta_null`` and, per parameter, ``theta_null``
    moved by ``relative_step`` of its prior width (backwards at the upper bound)."""
    theta_null = np.asarray(theta_null, dtype=float)
    n_par = theta_null.size
    ensemble = np.repeat(theta_null[None, :], n_par + 1, axis=0)
    ensemble[np.arange(1, n_par + 1), np.arange(n_par)] += _score_steps(problem, theta_null, relative_step)
    return ensemble


def _score_steps(problem: CalibrationProblem, theta_null: np.ndarray, relative_step: float) -> np.ndarray:
    steps = relative_step * (problem.upper - problem.lower)
    return np.where(np.asarray(theta_null, dtype=float) + steps > problem.upper, -steps, steps)


def score_test(
    problem: CalibrationProblem,
    theta_null: np.ndarray,
    effect_columns: Sequence[int],
    *,
    relative_step: float = 1e-3,
    sample_fractions: Sequence[float] | None = None,
) -> ScoreTest:
    """Score test for the parameters in ``effect_columns`` of ``problem`` at ``theta_null``.

    Each target's rows are whitened by its own noise variance σ̂ₖ² = RSSₖ/(nₖ(1 − p/n)) and scaled
    by its effective sample fraction fₖ = n_eff,ₖ/nₖ, so S = Σₖ fₖ·ΔRSSₖ/σ̂ₖ² does not depend on the
    weights the targets were given. Degrees of freedom: the effect parameters the model lets act at
    the null (a non-zero Jacobian column), with the χ̄² mixture for those whose null is a bound.

    :param theta_null: θ with the base parameters at their estimate and the effect's at the null.
    :param effect_columns: columns of θ that belong to the effect.
    :param relative_step: forward-difference step as a share of each parameter's prior width
        (taken backwards when the parameter sits at its upper bound).
    :param sample_fractions: fₖ per target in the problem's order; from each target's base residuals when None.
    """
    ensemble = score_ensemble(problem, theta_null, relative_step)
    n_par = ensemble.shape[1]
    steps = _score_steps(problem, theta_null, relative_step)
    residuals = problem.weighted_residuals(problem.run(ensemble))
    base_residual = residuals[0]
    jacobian = (residuals[1:] - base_residual).T / steps
    rows = target_rows(problem)
    n = base_residual.size
    counts = np.bincount(rows, minlength=len(problem.target_keys)).astype(float)
    if sample_fractions is None:
        sample_fractions = [effective_sample_fraction(base_residual[rows == k]) for k in range(counts.size)]
    effect = [int(c) for c in effect_columns]
    base = [c for c in range(n_par) if c not in effect]
    noise_variance = per_target_rss(base_residual, rows) / np.maximum(counts * (1.0 - len(base) / n), 1.0)
    row_weight = np.sqrt(np.divide(np.asarray(sample_fractions, dtype=float), noise_variance,
                                   out=np.zeros(counts.size), where=noise_variance > 0))[rows]
    whitened_residual, whitened_jacobian = row_weight * base_residual, row_weight[:, None] * jacobian

    # the Gauss–Newton step solves J δ ≈ −r (residual r = y − ŷ decreases along −J^+ r); with the base
    # free, what the effect adds is the bounded least squares of −r's part outside the base's span on
    # the effect columns' parts outside it
    def outside_base(columns: np.ndarray) -> np.ndarray:
        if not base:
            return columns
        coefficients, *_ = np.linalg.lstsq(whitened_jacobian[:, base], columns, rcond=1e-10)
        return columns - whitened_jacobian[:, base] @ coefficients

    target = outside_base(-whitened_residual)
    directions = outside_base(whitened_jacobian[:, effect])
    step = lsq_linear(directions, target, bounds=(problem.lower[effect] - theta_null[effect],
                                                  problem.upper[effect] - theta_null[effect])).x
    left = directions @ step - target
    statistic = max(float(np.dot(target, target) - np.dot(left, left)), 0.0)
    acting = [c for c in effect if np.any(jacobian[:, c] != 0.0)]
    on_bound = sum(bool(np.isclose(theta_null[c], problem.lower[c]) or np.isclose(theta_null[c], problem.upper[c]))
                   for c in acting)
    moved = [c for c, d in zip(effect, step) if abs(d) > 1e-9 * (problem.upper[c] - problem.lower[c]) and c in acting]
    return ScoreTest(
        statistic=statistic, loglik_gain=statistic / 2.0,
        p_value=bounded_null_p_value(statistic, len(acting) - on_bound, on_bound),
        active_parameters=tuple(problem.parameter_names[c] for c in moved),
    )


def delta_bic(rss_base, rss_effect, n_effective, n_extra: int) -> float:
    """ΔBIC = Σₖ n_eff,ₖ·ln(RSS₁,ₖ/RSS₀,ₖ) + k·ln(Σₖ n_eff,ₖ) over the targets k (each with its own
    noise variance; scalars for one target); negative favours the effect. ``n_extra``: every
    parameter the hypothesis frees beyond the base's."""
    rss_base, rss_effect, n_effective = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (rss_base, rss_effect, n_effective))
    ratio = np.maximum(rss_effect, 1e-300) / np.maximum(rss_base, 1e-300)
    counted = np.isfinite(ratio) & (n_effective > 0)  # a target without values in the window says nothing
    return float(np.sum(n_effective[counted] * np.log(ratio[counted])) + n_extra * np.log(np.sum(n_effective[counted])))


def rank_evidence(
    evidence: Sequence[EffectEvidence], *, bic_threshold: float = BIC_THRESHOLD,
    min_test_improvement: float = MIN_TEST_IMPROVEMENT,
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
        return (not item.significant, bool(item.demoted), -round(improvement, 2), bic, len(item.parameter_names),
                item.effect, item.node)

    return sorted(evidence, key=key)


def step_errors(
    observed: Mapping[str, np.ndarray], predicted: Mapping[str, np.ndarray], scales: Mapping[str, float]
) -> np.ndarray:
    """Each step's share of :func:`weighted_test_error`: Σ_targets ((y − ŷ)/s)² / n_target (0 where
    a target was not measured)."""
    return residual_step_errors({key: values - predicted[key] for key, values in observed.items()}, scales)


def residual_step_errors(residuals: Mapping[str, np.ndarray], scales: Mapping[str, float]) -> np.ndarray:
    """Each step's Σ_targets (r/s)² / n_target of residuals r = y − ŷ aligned in time (NaN where a
    target was not measured, counted as 0)."""
    total = np.zeros(next(iter(residuals.values())).shape[-1])
    for key, values in residuals.items():
        mask = np.isfinite(values)
        if mask.any():
            total[mask] += (values[mask] / scales[key]) ** 2 / mask.sum()
    return total


def weighted_test_error(
    observed: Mapping[str, np.ndarray], predicted: Mapping[str, np.ndarray], scales: Mapping[str, float]
) -> float:
    """Σ_targets mean(((y − ŷ)/s)²) over the measured points: the error the ranking compares."""
    return float(step_errors(observed, predicted, scales).sum())
