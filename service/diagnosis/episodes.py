"""When the model fails: runs of steps where the measurement leaves the model, as readable spans.

A step fails when the measurement ``y`` lies outside a prediction interval ``[lower, upper]``
(deviation: the signed distance beyond the nearer bound) or, for a point fit, when its residual
``|e| > robust_threshold · σ̂`` with ``σ̂ = 1.4826 · median(|e − median(e)|)`` and ``|e| ≥ min_deviation``
(deviation: ``e``). NaN steps never fail; failing steps at most ``merge_gap_steps`` apart merge into
one episode; episodes shorter than ``min_duration_steps`` are dropped. An episode covers
``[start, end)``, ``end`` the step after its last failing one. Rationale: ``docs/diagnosis.md``, "Episodes".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.graph.units import difference_text

__all__ = ["Episode", "find_episodes", "MAD_TO_SIGMA"]

#: σ of a normal variable per unit of median absolute deviation.
MAD_TO_SIGMA = 1.4826


def _significant(value: float, digits: int = 3) -> str:
    """``value`` to ``digits`` significant digits, without exponent notation or trailing zeros."""
    if value == 0 or not np.isfinite(value):
        return f"{value:g}"
    decimals = max(digits - 1 - int(np.floor(np.log10(abs(value)))), 0)
    text = f"{round(value, decimals):.{decimals}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def _minute(timestamp: np.datetime64) -> str:
    return str(np.datetime64(timestamp, "m")).replace("T", " ")


@dataclass(frozen=True)
class Episode:
    """A span ``[start, end)`` where the measurement leaves the model.

    ``peak_deviation`` (largest |deviation|, signed) and ``mean_deviation`` are over the span's
    finite steps, in ``unit``; ``reference`` is what was left ("the model" or "the prediction
    interval"); ``n_steps`` counts the steps of the span, ``n_failing`` those that failed.
    """

    start: np.datetime64
    end: np.datetime64
    n_steps: int
    n_failing: int
    peak_deviation: float
    mean_deviation: float
    both_sides: bool
    reference: str
    unit: str = ""
    logged_unit: str = ""

    @property
    def duration_h(self) -> float:
        return float((self.end - self.start) / np.timedelta64(1, "s")) / 3600.0

    def describe(self) -> str:
        """"2017-09-12 06:10 – 18:40 (12.5 h): measured above the model by up to 16.2 °F"."""
        start, end = _minute(self.start), _minute(self.end)
        if end[:10] == start[:10]:
            end = end[11:]
        if self.both_sides:
            side = f"on both sides of {self.reference}, by up to"
        else:
            side = f"{'above' if self.peak_deviation > 0 else 'below'} {self.reference} by up to"
        size = difference_text(abs(self.peak_deviation), self.unit, self.logged_unit, _significant)
        return f"{start} – {end} ({_significant(self.duration_h)} h): measured {side} {size}"

    def to_dict(self) -> dict:
        return {"start": str(self.start), "end": str(self.end), "duration_h": self.duration_h,
                "n_steps": self.n_steps, "n_failing": self.n_failing, "peak_deviation": self.peak_deviation,
                "mean_deviation": self.mean_deviation, "unit": self.unit,
                **({"logged_unit": self.logged_unit} if self.logged_unit else {}), "text": self.describe()}


def _as_series(name: str, values: np.ndarray | None, n: int) -> np.ndarray | None:
    if values is None:
        return None
    values = np.asarray(values, dtype=float)
    if values.shape != (n,):
        raise ValueError(f"{name} has shape {values.shape}, expected ({n},) like the timestamps")
    return values


def find_episodes(
    timestamps: np.ndarray,
    measured: np.ndarray,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    residual: np.ndarray | None = None,
    *,
    min_duration_steps: int = 3,
    merge_gap_steps: int = 2,
    robust_threshold: float = 3.0,
    min_deviation: float = 0.0,
    unit: str = "",
    logged_unit: str = "",
) -> list[Episode]:
    """Episodes where ``measured`` leaves ``[lower, upper]`` or, for a point fit, where ``residual``
    (= measured − predicted) is large (module docstring), in time order.

    :param timestamps: ``ndarray[n_t]`` of ``datetime64`` (or ISO strings), increasing.
    :param measured: ``ndarray[n_t]`` measurement, NaN where missing.
    :param lower, upper: ``ndarray[n_t]`` prediction interval (give both), or None.
    :param residual: ``ndarray[n_t]`` measured − predicted, used when no interval is given.
    :param min_deviation: smallest |residual| that can fail (point fits), in ``unit``.
    :param unit: unit label of the measurement for the text ("°F", "K").
    :param logged_unit: the unit its column was logged in, where it differs: the text gives the size in both.
    """
    timestamps = np.asarray(timestamps, dtype="datetime64[s]")
    n = len(timestamps)
    if n > 1 and not (np.diff(timestamps) > np.timedelta64(0, "s")).all():
        raise ValueError("timestamps must be strictly increasing")
    measured = _as_series("measured", measured, n)
    lower, upper, residual = (_as_series(k, v, n) for k, v in
                              (("lower", lower), ("upper", upper), ("residual", residual)))
    if (lower is None) != (upper is None):
        raise ValueError("give both lower and upper (a prediction interval), or neither and a residual")
    if min_duration_steps < 1 or merge_gap_steps < 0:
        raise ValueError(f"min_duration_steps must be ≥ 1 and merge_gap_steps ≥ 0, "
                         f"got {min_duration_steps}, {merge_gap_steps}")
    if lower is not None:
        deviation = np.where(measured > upper, measured - upper, np.where(measured < lower, measured - lower, 0.0))
        deviation[~(np.isfinite(measured) & np.isfinite(lower) & np.isfinite(upper))] = np.nan
        fails = np.nan_to_num(deviation) != 0.0
        reference = "the prediction interval"
    elif residual is not None:
        deviation = np.where(np.isfinite(measured), residual, np.nan)
        finite = deviation[np.isfinite(deviation)]
        if finite.size == 0:
            return []
        sigma = MAD_TO_SIGMA * np.median(np.abs(finite - np.median(finite)))
        limit = max(robust_threshold * sigma, min_deviation)
        fails = np.abs(np.nan_to_num(deviation)) > limit
        reference = "the model"
    else:
        raise ValueError("give a prediction interval (lower and upper) or the residual of a point fit")

    failing = np.flatnonzero(fails)
    if failing.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(failing) > merge_gap_steps + 1)
    firsts = np.concatenate([[failing[0]], failing[breaks + 1]])
    lasts = np.concatenate([failing[breaks], [failing[-1]]])
    step = np.median(np.diff(timestamps)) if n > 1 else np.timedelta64(0, "s")
    episodes = []
    for first, last in zip(firsts, lasts):
        if last - first + 1 < min_duration_steps:
            continue
        span = deviation[first:last + 1]
        span = span[np.isfinite(span)]
        failing_span = span[span != 0.0] if lower is not None else span[np.abs(span) > limit]
        peak = float(span[np.argmax(np.abs(span))])
        episodes.append(Episode(
            start=timestamps[first], end=timestamps[last] + step, n_steps=int(last - first + 1),
            n_failing=int(fails[first:last + 1].sum()), peak_deviation=peak, mean_deviation=float(span.mean()),
            both_sides=bool((failing_span > 0).any() and (failing_span < 0).any()), reference=reference, unit=unit,
            logged_unit=logged_unit,
        ))
    return episodes
