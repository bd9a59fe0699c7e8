"""What a residual depends on, when no effect in the catalog explains it: a pointer for the engineer.

For every candidate signal x (measured series and model outputs near the failing sensor) the
Pearson correlation of the residual e(t) with x(t − ℓ) is computed for lags ℓ = 0 … ``max_lag_steps``
on the steps where both are finite; the strongest |ρ| and its lag rank the signals. A multiple
regression of e on the top signals at their lags gives the share of the residual's variance they
explain together (R²). Constant signals are skipped with the reason.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["Dependence", "residual_dependence", "joint_r2"]


@dataclass(frozen=True)
class Dependence:
    signal: str
    correlation: float
    lag_steps: int
    n: int

    def describe(self, step_s: float | None = None) -> str:
        lag = f"{self.lag_steps} steps" if step_s is None else f"{self.lag_steps * step_s / 60:.0f} min"
        return f"residual correlates {self.correlation:+.2f} with {self.signal} (lag {lag}, {self.n} steps)"

    def to_dict(self) -> dict:
        return {"signal": self.signal, "correlation": self.correlation, "lag_steps": self.lag_steps, "n": self.n}


def _lagged(x: np.ndarray, lag: int) -> np.ndarray:
    if lag == 0:
        return x
    out = np.full_like(x, np.nan)
    out[lag:] = x[:-lag]
    return out


def residual_dependence(
    residual: np.ndarray, signals: Mapping[str, np.ndarray], *, max_lag_steps: int = 12, min_steps: int = 20,
) -> tuple[list[Dependence], list[str]]:
    """Signals ranked by the strongest |correlation| with ``residual`` over lags; and skip reasons."""
    residual = np.asarray(residual, dtype=float)
    ranked: list[Dependence] = []
    skipped: list[str] = []
    for name, values in signals.items():
        values = np.asarray(values, dtype=float)
        finite = values[np.isfinite(values)]
        if finite.size < min_steps or np.ptp(finite) == 0.0:
            skipped.append(f"{name}: constant or too few values")
            continue
        best = None
        for lag in range(max_lag_steps + 1):
            x = _lagged(values, lag)
            both = np.isfinite(x) & np.isfinite(residual)
            if both.sum() < min_steps or np.std(x[both]) == 0 or np.std(residual[both]) == 0:
                continue
            rho = float(np.corrcoef(residual[both], x[both])[0, 1])
            if best is None or abs(rho) > abs(best.correlation):
                best = Dependence(name, rho, lag, int(both.sum()))
        if best is not None:
            ranked.append(best)
    ranked.sort(key=lambda d: -abs(d.correlation))
    return ranked, skipped


def joint_r2(residual: np.ndarray, signals: Mapping[str, np.ndarray], dependences: list[Dependence]) -> float:
    """R² of ``residual`` regressed on the listed signals at their lags (with an intercept)."""
    columns = [_lagged(np.asarray(signals[d.signal], float), d.lag_steps) for d in dependences]
    if not columns:
        return 0.0
    design = np.column_stack([np.ones_like(residual)] + columns)
    rows = np.isfinite(design).all(axis=1) & np.isfinite(residual)
    if rows.sum() <= design.shape[1]:
        return float("nan")
    coef, *_ = np.linalg.lstsq(design[rows], residual[rows], rcond=None)
    fitted = design[rows] @ coef
    total = np.sum((residual[rows] - residual[rows].mean()) ** 2)
    return float(1.0 - np.sum((residual[rows] - fitted) ** 2) / total) if total > 0 else float("nan")
