"""What a residual depends on, when no effect in the catalog explains it: a pointer for the engineer.

Every candidate signal x is ranked by its strongest Pearson |ρ| of the residual ``e(t)`` with
``x(t − ℓ)`` over the lags ``ℓ = 0 … max_lag_steps`` (steps where both are finite and ``valid``); for
the top ``n_joint`` at their best lags, ``partial_correlation`` (with the signals ranked above
regressed out of both, intercept included) and ``cumulative_r2`` (R² of the residual on the top k
together). Constant or too short signals (fewer than ``min_steps``) come last with ``skipped_reason``.
:func:`time_trend`: the residual's straight-line trend in time. More: ``docs/diagnosis.md``, "When
nothing is found".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["Dependence", "residual_dependence", "COLLINEAR_SHARE", "TimeTrend", "time_trend", "distinct_signals",
           "SAME_SIGNAL_CORRELATION"]

#: A signal whose variance left after regressing on the signals above is below this share of its
#: own is a linear combination of them: its partial correlation is reported as 0.
COLLINEAR_SHARE = 1e-10
#: Two signals this correlated (|ρ| over their common finite steps) are one signal under two names.
SAME_SIGNAL_CORRELATION = 0.99
#: A straight line in time that explains less than this share of a residual's variance is no trend.
TREND_SHARE = 0.25


@dataclass(frozen=True)
class Dependence:
    """How the residual follows one signal: ``e(t)`` vs ``signal(t − lag_steps)``.

    ``correlation`` is Pearson's ρ over ``n_steps`` steps; ``rank`` is 1 for the strongest;
    ``partial_correlation`` and ``cumulative_r2`` are set for the top ``n_joint`` signals (module
    docstring; the partial correlation is 0 for a signal that is a linear combination of those
    above), else None;
    ``skipped_reason`` is set (and the numbers NaN) for a signal that could not be ranked.
    """

    signal: str
    lag_steps: int
    correlation: float
    n_steps: int
    partial_correlation: float | None = None
    cumulative_r2: float | None = None
    rank: int | None = None
    skipped_reason: str | None = None

    def describe(self, step_s: float | None = None) -> str:
        """One sentence: "the residual follows outdoor air temperature 30 min earlier (ρ = +0.81 over
        1200 steps); alone it explains 66 % of the residual's variance"."""
        if self.skipped_reason is not None:
            return f"{self.signal}: not ranked, {self.skipped_reason}"
        if self.lag_steps == 0:
            when = "at the same step"
        elif step_s is None:
            when = f"{self.lag_steps} steps earlier"
        else:
            minutes = self.lag_steps * step_s / 60.0
            when = f"{minutes:.0f} min earlier" if minutes < 120 else f"{minutes / 60:.1f} h earlier"
        text = f"the residual follows {self.signal} {when} (ρ = {self.correlation:+.2f} over {self.n_steps} steps)"
        if self.cumulative_r2 is None:
            return text
        if self.rank == 1:
            return text + f"; alone it explains {100 * self.cumulative_r2:.0f} % of the residual's variance"
        above = "signal" if self.rank == 2 else "signals"
        return text + (f"; given the {self.rank - 1} {above} ranked above, partial ρ = "
                       f"{self.partial_correlation:+.2f}, together they explain {100 * self.cumulative_r2:.0f} % "
                       "of the residual's variance")

    def to_dict(self) -> dict:
        return {"signal": self.signal, "lag_steps": self.lag_steps, "correlation": self.correlation,
                "n_steps": self.n_steps, "partial_correlation": self.partial_correlation,
                "cumulative_r2": self.cumulative_r2, "rank": self.rank, "skipped_reason": self.skipped_reason}


@dataclass(frozen=True)
class TimeTrend:
    """The least-squares line of a residual against time: ``per_day`` (the residual's unit a day),
    the share ``r2`` of the residual's variance it explains, over ``n_steps`` finite steps."""

    per_day: float
    r2: float
    n_steps: int

    def describe(self, unit: str) -> str:
        """"it drifts +0.31 K a day (the trend explains 64 % of its variance)", or, where the line
        explains less than :data:`TREND_SHARE` of it, that it has no trend."""
        if self.r2 < TREND_SHARE:
            return f"it has no trend in time (a straight line explains {100 * self.r2:.0f} % of its variance)"
        return (f"it drifts {self.per_day:+.2g} {unit} a day (the trend explains {100 * self.r2:.0f} % of its "
                "variance)")

    def to_dict(self) -> dict:
        return {"per_day": self.per_day, "r2": self.r2, "n_steps": self.n_steps}


def time_trend(residual: np.ndarray, timestamps: np.ndarray) -> TimeTrend | None:
    """The straight-line trend of ``residual`` ``ndarray[n_t]`` (NaN: not measured) against its
    ``timestamps`` (datetime64); None with fewer than 3 finite steps or a constant residual."""
    residual = np.asarray(residual, dtype=float)
    days = (np.asarray(timestamps) - np.asarray(timestamps)[0]) / np.timedelta64(1, "D")
    use = np.isfinite(residual)
    if use.sum() < 3 or np.ptp(residual[use]) == 0 or np.ptp(days[use]) == 0:
        return None
    slope, intercept = np.polyfit(days[use], residual[use], 1)
    left = residual[use] - (slope * days[use] + intercept)
    r2 = 1.0 - float(np.sum(left ** 2) / np.sum((residual[use] - residual[use].mean()) ** 2))
    return TimeTrend(float(slope), r2, int(use.sum()))


def _lagged(x: np.ndarray, lag: int) -> np.ndarray:
    """``x(t − lag)``: shifted later by ``lag`` steps, NaN where unknown."""
    if lag == 0:
        return x
    out = np.full_like(x, np.nan)
    out[lag:] = x[:-lag]
    return out


def _residual_of(y: np.ndarray, design: np.ndarray) -> np.ndarray:
    """Least-squares residual of ``y`` on ``design`` (which holds the intercept column)."""
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return y - design @ coef


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    denominator = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / denominator) if denominator > 0 else float("nan")


def residual_dependence(
    residual: np.ndarray,
    candidate_signals: Mapping[str, np.ndarray],
    *,
    max_lag_steps: int = 12,
    valid: np.ndarray | None = None,
    min_steps: int = 20,
    n_joint: int = 3,
) -> list[Dependence]:
    """Candidate signals ranked by their strongest |correlation| with ``residual`` over lags 0 …
    ``max_lag_steps``; the top ``n_joint`` with the regression view; skipped signals last.

    :param residual: ``ndarray[n_t]`` measured − predicted (NaN: not measured).
    :param candidate_signals: name → ``ndarray[n_t]`` on the same time steps.
    :param valid: ``ndarray[n_t]`` of bool, steps of the residual to use (default all).
    """
    residual = np.asarray(residual, dtype=float)
    if residual.ndim != 1:
        raise ValueError(f"residual has shape {residual.shape}, expected (n_steps,)")
    if max_lag_steps < 0:
        raise ValueError(f"max_lag_steps must be ≥ 0, got {max_lag_steps}")
    use = np.isfinite(residual)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != residual.shape:
            raise ValueError(f"valid has shape {valid.shape}, residual {residual.shape}: they must agree")
        use &= valid
    if not use.any() or np.ptp(residual[use]) == 0:
        raise ValueError("the residual is constant (or has no valid step): there is nothing to explain")

    signals: dict[str, np.ndarray] = {}
    ranked: list[Dependence] = []
    skipped: list[Dependence] = []
    for name, values in candidate_signals.items():
        values = np.asarray(values, dtype=float)
        if values.shape != residual.shape:
            raise ValueError(f"signal {name!r} has shape {values.shape}, residual {residual.shape}: they must agree")
        signals[name] = values
        seen = values[use & np.isfinite(values)]
        reason = (f"only {seen.size} finite valid steps (fewer than {min_steps})" if seen.size < min_steps
                  else "constant over the valid steps" if np.ptp(seen) == 0 else None)
        best: Dependence | None = None
        for lag in range(max_lag_steps + 1) if reason is None else ():
            x = _lagged(values, lag)
            both = use & np.isfinite(x)
            if both.sum() < min_steps:
                continue
            rho = _correlation(residual[both], x[both])
            if np.isfinite(rho) and (best is None or abs(rho) > abs(best.correlation)):
                best = Dependence(name, lag, rho, int(both.sum()))
        if best is None:
            skipped.append(Dependence(name, 0, float("nan"), int(seen.size),
                                      skipped_reason=reason or "constant or too short at every lag"))
        else:
            ranked.append(best)
    ranked.sort(key=lambda d: -abs(d.correlation))
    ranked = [replace(d, rank=k + 1) for k, d in enumerate(ranked)]

    columns: list[np.ndarray] = []
    for k, dependence in enumerate(ranked[:n_joint]):
        x = _lagged(signals[dependence.signal], dependence.lag_steps)
        rows = use & np.isfinite(x)
        for column in columns:
            rows &= np.isfinite(column)
        if rows.sum() < min_steps + k + 2:
            break
        e, xr = residual[rows], x[rows]
        above = np.column_stack([np.ones(int(rows.sum()))] + [c[rows] for c in columns])
        e_left = _residual_of(e, above)
        if np.sum(e_left ** 2) <= 1e-12 * np.sum((e - e.mean()) ** 2):
            break  # the signals above explain the residual whole: nothing is left to correlate with
        x_cleared = _residual_of(xr, above)
        new = x_cleared @ x_cleared > COLLINEAR_SHARE * np.sum((xr - xr.mean()) ** 2)
        partial = _correlation(e_left, x_cleared) if new else 0.0
        r2 = 1.0 - np.sum(_residual_of(e, np.column_stack([above, xr])) ** 2) / np.sum((e - e.mean()) ** 2)
        ranked[k] = replace(dependence, partial_correlation=partial, cumulative_r2=float(r2))
        columns.append(x)
    return ranked + skipped


def distinct_signals(signals: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``signals`` (name → series aligned in time) without those that are one before them under a
    second name, |ρ| ≥ :data:`SAME_SIGNAL_CORRELATION` over their common finite steps (a measured input
    and a model's copy of it; a fan's air flow and its speed): the first of each kept."""
    kept: dict[str, np.ndarray] = {}
    for name, values in signals.items():
        if not any(_same_signal(values, other) for other in kept.values()):
            kept[name] = values
    return kept


def _same_signal(a: np.ndarray, b: np.ndarray) -> bool:
    both = np.isfinite(a) & np.isfinite(b)
    if both.sum() < 3 or np.std(a[both]) == 0 or np.std(b[both]) == 0:
        return False
    return abs(float(np.corrcoef(a[both], b[both])[0, 1])) >= SAME_SIGNAL_CORRELATION
