"""When the model fails: runs of steps where measurements leave the prediction, as readable spans.

For a point fit a step *fails* when ``|y − ŷ| > threshold · σ`` with σ the robust spread of the
residuals (``1.4826 · MAD`` around their median, so a fault affecting a minority of the steps does
not hide itself by inflating σ); with a prediction interval it fails when ``y`` lies outside
``[lower, upper]``. Failing runs separated by at most ``merge_gap_steps`` steps are merged; runs
shorter than ``min_duration_steps`` are dropped (a spike is not an episode). NaN steps never fail.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Episode", "find_episodes"]


@dataclass(frozen=True)
class Episode:
    """A span where the measurement leaves the model: ``peak`` and ``mean`` of y − ŷ (signed)."""

    start: np.datetime64
    end: np.datetime64
    n_steps: int
    duration_h: float
    peak: float
    mean: float
    unit: str = ""

    def describe(self) -> str:
        side = "above" if self.mean > 0 else "below"
        start = str(self.start).replace("T", " ")[:16]
        end = str(self.end).replace("T", " ")[:16]
        return (f"{start} – {end} ({self.duration_h:.1f} h): measured {side} the model by up to "
                f"{abs(self.peak):.2f} {self.unit}".rstrip())

    def to_dict(self) -> dict:
        return {"start": str(self.start), "end": str(self.end), "duration_h": self.duration_h,
                "peak": self.peak, "mean": self.mean, "text": self.describe()}


def find_episodes(
    timestamps: np.ndarray,
    observed: np.ndarray,
    predicted: np.ndarray,
    *,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    threshold: float = 3.0,
    floor: float = 0.0,
    min_duration_steps: int = 3,
    merge_gap_steps: int = 2,
    unit: str = "",
) -> list[Episode]:
    """Episodes where ``observed`` leaves ``predicted`` (or ``[lower, upper]``), see the module docstring.

    :param floor: smallest |y − ŷ| that can fail (e.g. the sensor accuracy), in the target's unit.
    """
    residual = np.asarray(observed, float) - np.asarray(predicted, float)
    finite = np.isfinite(residual)
    if lower is not None and upper is not None:
        fails = finite & ((observed < lower) | (observed > upper))
    else:
        values = residual[finite]
        if values.size == 0:
            return []
        sigma = 1.4826 * np.median(np.abs(values - np.median(values)))
        limit = max(threshold * sigma, floor)
        fails = finite & (np.abs(residual - np.median(values)) > limit)
    index = np.flatnonzero(fails)
    if index.size == 0:
        return []
    runs = [[index[0], index[0]]]
    for i in index[1:]:
        if i - runs[-1][1] <= merge_gap_steps + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    step_s = float(np.median(np.diff(timestamps).astype("timedelta64[s]").astype(float))) if len(timestamps) > 1 else 0.0
    episodes = []
    for start, end in runs:
        if end - start + 1 < min_duration_steps:
            continue
        span = residual[start:end + 1]
        span = span[np.isfinite(span)]
        peak = float(span[np.argmax(np.abs(span))])
        episodes.append(Episode(
            start=timestamps[start], end=timestamps[end], n_steps=int(end - start + 1),
            duration_h=(end - start + 1) * step_s / 3600.0, peak=peak, mean=float(span.mean()), unit=unit,
        ))
    return episodes
