"""Goodness-of-fit and interval metrics of one target on one window.

Over the ``n`` measured steps (NaN in ``y`` is left out), ``p`` estimated parameters: ``RMSE``,
``MAE``, ``R² = 1 − Σ(y − ŷ)² / Σ(y − ȳ)²``; ASHRAE Guideline 14-2014
``CV(RMSE) = sqrt(Σ(y − ŷ)² / (n − p)) / |ȳ| · 100 %`` and ``NMBE = Σ(y − ŷ) / ((n − p) · |ȳ|) · 100 %``
(> 0: the model under-predicts) with the hourly criteria CV(RMSE) ≤ 30 %, |NMBE| ≤ 10 % (not applied
on an interval scale such as °C, a mean near zero, or ``n ≤ p``); the residuals' lag-1
autocorrelation; per central interval of level ``1 − α`` the coverage ``c``, ``ACE = c − (1 − α)``
(the paper's Table 5) and the mean width. Definitions and reasons: ``docs/calibration.md``, *Metrics*.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from service.calibration.problem import INSTRUMENT_ACCURACY_FLOOR, RELATIVE_ACCURACY_FLOOR
from service.errors import CalibrationError

__all__ = [
    "TargetMetrics", "IntervalCoverage", "target_metrics", "effective_sample_fraction", "long_run_variance_factor",
    "INTERVAL_SCALE_UNITS", "on_interval_scale", "noise_level",
    "GUIDELINE14_HOURLY_CV_RMSE_PERCENT", "GUIDELINE14_HOURLY_NMBE_PERCENT",
]

#: Units whose zero is arbitrary: ratios to their mean are meaningless.
INTERVAL_SCALE_UNITS = frozenset({"degC", "degF", "°C", "°F", "DEG_C", "DEG_F"})
#: ASHRAE Guideline 14-2014, hourly calibration data.
GUIDELINE14_HOURLY_CV_RMSE_PERCENT = 30.0
GUIDELINE14_HOURLY_NMBE_PERCENT = 10.0
_MEAN_NEAR_ZERO_SHARE = 0.05


@dataclass(frozen=True)
class IntervalCoverage:
    """Coverage of one central prediction interval: nominal ``level``, empirical ``coverage``, ``ace``
    (coverage − level) and ``mean_width`` (target's unit)."""

    level: float
    coverage: float
    ace: float
    mean_width: float


@dataclass(frozen=True)
class TargetMetrics:
    """Metrics of one target on one window (definitions: the module docstring, ``docs/calibration.md``)."""

    target: str
    unit: str
    n: int
    n_parameters: int
    mean_observed: float
    rmse: float
    mae: float
    r2: float
    cv_rmse_percent: float
    nmbe_percent: float
    lag1_autocorrelation: float
    guideline14_applies: bool
    guideline14_pass: bool | None
    guideline14_note: str
    coverage: tuple[IntervalCoverage, ...] = ()
    noise: float = float("nan")  # the measurement noise σ the residual shows (:func:`noise_level`)

    def to_dict(self) -> dict:
        """Plain types only (floats, bools, str, lists): ready for JSON."""
        result = asdict(self)
        result["coverage"] = [asdict(c) for c in self.coverage]
        return result


def noise_level(values: np.ndarray, unit: str, observed: np.ndarray) -> float:
    """Measurement noise σ (RMS over the window) of a sensor from the second differences of its
    residual y − ŷ (``values``), floored at the instrument accuracy of its unit — for a unit without an
    absolute one (W, m³/s) 1 % of the mean magnitude of the ``observed`` reading
    (:data:`~service.calibration.problem.RELATIVE_ACCURACY_FLOOR`).

    Δ²e of white noise has standard deviation √6·σ; the first quartile of |Δ²e| is 0.3186·√6·σ for
    Gaussian noise, and stays a noise measure while model error bends the residual on up to half of
    the steps (a median would not). A meter without an absolute accuracy (power, flow) reads with
    noise in proportion to its reading, σₖ = c·|yₖ|: Δ²eₖ is divided by sₖ = √((y²ₖ₋₁ + 4y²ₖ + y²ₖ₊₁)/6)
    before the quartile gives c, and σ = c·√(mean y²) (one quartile of Δ²e would give the noise of the
    low readings).
    """
    second = np.diff(np.asarray(values, dtype=float), n=2)
    scale = 1.0  # σ per unit of the quartile: 1, or √(mean y²) for noise in proportion to the reading
    if unit not in INSTRUMENT_ACCURACY_FLOOR:
        squares = np.asarray(observed, dtype=float) ** 2
        local = np.sqrt((squares[:-2] + 4.0 * squares[1:-1] + squares[2:]) / 6.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            second = np.where(local > 0.0, second / local, np.nan)
        scale = float(np.sqrt(np.nanmean(squares)))
    second = second[np.isfinite(second)]
    sigma = scale * float(np.quantile(np.abs(second), 0.25)) / (0.3186 * np.sqrt(6.0)) if second.size else 0.0
    floor = INSTRUMENT_ACCURACY_FLOOR.get(unit, RELATIVE_ACCURACY_FLOOR * float(np.nanmean(np.abs(observed))))
    return max(sigma, floor)


def on_interval_scale(unit: str) -> bool:
    """``unit`` (a port unit or a QUDT IRI) has an arbitrary zero (°C, °F): ratios to its mean, CV(RMSE)
    and NMBE, mean nothing there."""
    return unit in INTERVAL_SCALE_UNITS or unit.rsplit("/", 1)[-1] in INTERVAL_SCALE_UNITS


def _guideline14(unit: str, mean: float, max_abs: float, dof: int, cv: float, nmbe: float):
    if dof <= 0:
        return False, None, f"n − p = {dof} ≤ 0: CV(RMSE) and NMBE undefined"
    if on_interval_scale(unit):
        return False, None, f"not applied: the mean of a value in {unit} depends on the zero of the scale"
    if not np.isfinite(cv):
        return False, None, f"not applied: mean {mean:.4g} is near zero (within the noise), the ratios say nothing"
    if abs(mean) < _MEAN_NEAR_ZERO_SHARE * max_abs or mean == 0.0:
        return False, None, (
            f"not applied: mean {mean:.4g} is near zero (below {100 * _MEAN_NEAR_ZERO_SHARE:.0f} % of "
            f"max |y| = {max_abs:.4g}), the ratios are unstable"
        )
    passed = cv <= GUIDELINE14_HOURLY_CV_RMSE_PERCENT and abs(nmbe) <= GUIDELINE14_HOURLY_NMBE_PERCENT
    return True, passed, (
        f"the hourly criteria (the finest Guideline 14 states, applied at the data's step) "
        f"CV(RMSE) ≤ {GUIDELINE14_HOURLY_CV_RMSE_PERCENT:.0f} %, "
        f"|NMBE| ≤ {GUIDELINE14_HOURLY_NMBE_PERCENT:.0f} %"
    )


def target_metrics(
    observed: np.ndarray,
    predicted: np.ndarray,
    *,
    n_parameters: int = 0,
    intervals: Mapping[float, tuple[np.ndarray, np.ndarray]] | None = None,
    unit: str = "",
    target: str = "",
) -> TargetMetrics:
    """Metrics of a prediction against the measured series of one target.

    :param observed: ``ndarray[n_steps]``, NaN where not measured.
    :param predicted: ``ndarray[n_steps]``, the point or median prediction.
    :param n_parameters: p, the number of estimated parameters (Guideline 14's n − p).
    :param intervals: ``{level: (lower, upper)}`` central prediction intervals, each ``ndarray[n_steps]``.
    :param unit: the target's unit (decides whether Guideline 14's criteria apply).
    :raises ValueError: for mismatched shapes.
    :raises CalibrationError: no measured step, or a non-finite prediction at a measured step (the
        message names the row).
    """
    y_all = np.asarray(observed, dtype=float)
    y_hat_all = np.asarray(predicted, dtype=float)
    label = f"target {target}: " if target else ""
    if y_all.ndim != 1 or y_hat_all.shape != y_all.shape:
        raise ValueError(f"{label}observed {y_all.shape} and predicted {y_hat_all.shape}: expected equal (n_steps,)")
    measured = np.isfinite(y_all)
    if not measured.any():
        raise CalibrationError(f"{label}no measured step in the window")
    bad = np.flatnonzero(measured & ~np.isfinite(y_hat_all))
    if bad.size:
        raise CalibrationError(f"{label}prediction is not finite at row {bad[0]}")
    y, y_hat = y_all[measured], y_hat_all[measured]
    n, p = y.size, int(n_parameters)
    error = y - y_hat
    mean = float(np.mean(y))
    total = float(np.sum((y - mean) ** 2))
    dof = n - p
    residual = np.where(measured, y_all - y_hat_all, np.nan)
    noise = noise_level(residual, unit, np.where(measured, y_all, np.nan))
    # relative to a mean no larger than the noise (a valve that stays shut), the ratios say nothing
    scaled = dof > 0 and abs(mean) > max(noise, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        cv = float(np.sqrt(np.sum(error**2) / dof) / abs(mean) * 100.0) if scaled else np.nan
        nmbe = float(np.sum(error) / (dof * abs(mean)) * 100.0) if scaled else np.nan
    applies, passed, note = _guideline14(unit, mean, float(np.max(np.abs(y))), dof, cv, nmbe)
    centred = residual - np.nanmean(residual)
    pairs = centred[:-1] * centred[1:]
    variance = float(np.nansum(centred**2))
    lag1 = float(np.nansum(pairs) / variance) if variance > 0.0 and np.isfinite(pairs).any() else np.nan
    coverage = []
    for level, (lower, upper) in sorted((intervals or {}).items()):
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        if lower.shape != y_all.shape or upper.shape != y_all.shape:
            raise ValueError(f"{label}interval {level}: bounds of shape {lower.shape}, expected {y_all.shape}")
        inside = (lower[measured] <= y) & (y <= upper[measured])
        share = float(np.mean(inside))
        width = float(np.mean(upper[measured] - lower[measured]))
        coverage.append(IntervalCoverage(float(level), share, share - float(level), width))
    return TargetMetrics(
        target=target, unit=unit, n=n, n_parameters=p, mean_observed=mean,
        rmse=float(np.sqrt(np.mean(error**2))), mae=float(np.mean(np.abs(error))),
        r2=1.0 - float(np.sum(error**2)) / total if total > 0.0 else np.nan,
        cv_rmse_percent=cv, nmbe_percent=nmbe, lag1_autocorrelation=lag1,
        guideline14_applies=applies, guideline14_pass=passed, guideline14_note=note,
        coverage=tuple(coverage), noise=noise,
    )


def effective_sample_fraction(residuals: np.ndarray) -> float:
    """n_eff / n = (1 − ρ₁)/(1 + ρ₁) from the lag-1 autocorrelation ρ₁ of ``residuals`` (one
    target's series, NaN-free), clipped to [1/n, 1]."""
    r = np.asarray(residuals, dtype=float)
    r = r - r.mean()
    denominator = float(np.dot(r, r))
    if r.size < 3 or denominator == 0.0:
        return 1.0
    rho = float(np.dot(r[1:], r[:-1]) / denominator)
    return float(np.clip((1.0 - rho) / (1.0 + rho), 1.0 / r.size, 1.0))


def long_run_variance_factor(series: np.ndarray) -> float:
    """σ²_LR/σ² of one target's residual series (NaN where not measured): the Newey–West estimate
    1 + 2 Σₗ (1 − l/(L + 1)) ρₗ over lags l = 1…L, ρₗ over the pairs measured l steps apart (a gap
    pairs nothing; concatenated windows pair only beyond a window's unscored warm-up), L from
    Andrews' AR(1) plug-in 1.1447·(α n)^(1/3), α = 4ρ₁²/((1 − ρ₁)²(1 + ρ₁)²). For AR(1) residuals
    it approaches (1 + ρ₁)/(1 − ρ₁); for a misfit that oscillates (a loop hunting) the lags cancel
    and it falls below 1 (the oscillation averages out of what it is fitted with). Bartlett's
    weights keep it ≥ 0; floored at 1/n."""
    r = np.asarray(series, dtype=float)
    measured = np.isfinite(r)
    n = int(measured.sum())
    if n < 3:
        return 1.0
    centred = np.where(measured, r - r[measured].mean(), 0.0)
    total = float(np.dot(centred, centred))
    if total == 0.0:
        return 1.0
    rho_1 = float(np.clip(np.dot(centred[:-1], centred[1:]) / total, -0.99, 0.99))
    alpha = 4.0 * rho_1**2 / ((1.0 - rho_1) ** 2 * (1.0 + rho_1) ** 2)
    lags = int(min(np.ceil(1.1447 * (alpha * n) ** (1.0 / 3.0)), r.size - 1))
    weighted = sum((1.0 - lag / (lags + 1.0)) * float(np.dot(centred[:-lag], centred[lag:])) / total
                   for lag in range(1, lags + 1))
    return max(1.0 / n, 1.0 + 2.0 * weighted)
