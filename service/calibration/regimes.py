"""Operating regimes: clusters of operating states with rules an engineer can read.

Method (RWTH Aachen): mini-batch k-means on the boundary inputs and commands and their smoothed
rates (:func:`smoothed_rate`), robustly standardised (:func:`robust_spread`) and clipped to
±:data:`Z_CLIP`; k by the mean silhouette unless given; regimes numbered by decreasing share of
time. A shallow decision tree on the unscaled features reproduces the labels: its paths are the
rules (``rules_``), and :meth:`OperatingRegimes.predict` applies the tree, so the rule a user reads
is the rule applied. Steps with a non-finite input or rate are labelled −1. Scaling, selection and
rule text: ``docs/calibration.md``, *Operating regimes*.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.cluster import MiniBatchKMeans
from sklearn.metrics import silhouette_score
from sklearn.model_selection import cross_val_score
from sklearn.tree import DecisionTreeClassifier
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from service.errors import CalibrationError

__all__ = [
    "OperatingRegimes", "RuleCondition", "smoothed_rate", "per_regime_metrics", "worst_regime",
    "robust_spread", "SILHOUETTE_SUBSAMPLE", "Z_CLIP", "NORMAL_5_95_RANGE",
]

#: Largest number of steps the silhouette criterion is evaluated on (a seeded subsample).
SILHOUETTE_SUBSAMPLE = 2000
#: Robust z-scores are clipped to ±Z_CLIP before clustering.
Z_CLIP = 5.0
#: Width of the 5–95 % range of a normal variable in standard deviations (2 · 1.645).
NORMAL_5_95_RANGE = 3.29
#: Units written as their difference unit in a rate ("K/h", not "°C/h").
_RATE_UNITS = {"°C": "K", "degC": "K"}


def smoothed_rate(values: np.ndarray, smoothing_steps: int, step_s: float | None = None) -> np.ndarray:
    """Smoothed first derivative of every column of ``values`` (``ndarray[n_t, n_f]``).

    ``x̄(t)`` is the centred moving average over ``smoothing_steps`` (odd) steps; near the ends of
    the series the window shrinks symmetrically (to ``2·min(t, n − 1 − t) + 1`` steps), so a linear
    ramp stays exact; a window touching a NaN gives NaN (and so the rate one step further). The
    rate is ``numpy.gradient(x̄)`` (central difference, one-sided at the ends) per step, or per hour
    when ``step_s`` (seconds) is given.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim != 2:
        raise ValueError(f"values have shape {values.shape}, expected (n_steps, n_features)")
    if smoothing_steps < 1 or smoothing_steps % 2 == 0:
        raise CalibrationError(f"smoothing_steps must be an odd positive integer, got {smoothing_steps}")
    n = len(values)
    if n < 2:
        return np.zeros_like(values)
    t = np.arange(n)
    half = np.minimum(smoothing_steps // 2, np.minimum(t, n - 1 - t))
    finite = np.isfinite(values)
    zero = np.zeros((1, values.shape[1]))
    total = np.vstack([zero, np.cumsum(np.where(finite, values, 0.0), axis=0)])
    gaps = np.vstack([zero, np.cumsum(~finite, axis=0)])
    upper, lower = t + half + 1, t - half
    smooth = (total[upper] - total[lower]) / (2 * half + 1)[:, None]
    smooth[(gaps[upper] - gaps[lower]) > 0] = np.nan
    rates = np.gradient(smooth, axis=0)
    return rates * (3600.0 / step_s) if step_s is not None else rates


def robust_spread(values: np.ndarray) -> np.ndarray:
    """Per column ``s = (q95 − q5) / 3.29``; the standard deviation where that is 0; 1 if constant."""
    low, high = np.percentile(values, [5, 95], axis=0)
    std = values.std(axis=0)
    return np.where(high > low, (high - low) / NORMAL_5_95_RANGE, np.where(std > 0, std, 1.0))


def _range_decimals(spread: float) -> int:
    """Decimals of the power of ten at or below 2 % of ``spread`` (negative: tens, hundreds …)."""
    return -math.floor(math.log10(spread / 50.0)) if spread > 0 else 2


def _number(value: float, range_decimals: int) -> str:
    """``value`` rounded to its feature's resolution and to at most 3 significant digits, without
    trailing zeros."""
    significant = 2 - math.floor(math.log10(abs(value))) if value != 0 else range_decimals
    decimals = min(range_decimals, significant)
    text = f"{round(value, decimals) + 0.0:.{max(decimals, 0)}f}"  # + 0.0 turns -0.0 into 0.0
    return text.rstrip("0").rstrip(".") if "." in text else text


@dataclass(frozen=True)
class RuleCondition:
    """``lower < feature ≤ upper`` (either bound may be None) on one feature of the rule tree.

    ``signal`` is the input's name; ``is_rate`` marks its smoothed derivative (``unit`` is then the
    rate's unit, e.g. ``"K/h"``); ``range_decimals`` is the feature's resolution in the text (the
    power of ten at or below 2 % of its 5–95 % range; at most 3 significant digits in any case).
    """

    feature: int
    signal: str
    unit: str
    is_rate: bool
    lower: float | None
    upper: float | None
    range_decimals: int

    def _quantity(self, value: float) -> str:
        text = _number(value, self.range_decimals)
        if not self.unit or self.unit == "1":
            return text
        return f"{text}{self.unit}" if self.unit in ("%", "/h", "/step") else f"{text} {self.unit}".rstrip()

    def describe(self) -> str:
        """The condition in words: "supply fan speed > 0.31", "outdoor air temperature rising faster
        than 0.5 K/h", "heating valve position between 0.2 and 0.8"."""
        low, high = self.lower, self.upper
        if not self.is_rate:
            if low is not None and high is not None:
                return f"{self.signal} between {_number(low, self.range_decimals)} and {self._quantity(high)}"
            if low is not None:
                return f"{self.signal} > {self._quantity(low)}"
            return f"{self.signal} ≤ {self._quantity(high)}"
        if low is not None and high is not None:
            return (f"{self.signal} changing at a rate between {_number(low, self.range_decimals)} and "
                    f"{self._quantity(high)}")
        zero = 0.5 * 10.0 ** -self.range_decimals
        if low is not None:
            if abs(low) < zero:
                return f"{self.signal} rising"
            return (f"{self.signal} rising faster than {self._quantity(low)}" if low > 0
                    else f"{self.signal} not falling faster than {self._quantity(-low)}")
        if abs(high) < zero:
            return f"{self.signal} steady or falling"
        return (f"{self.signal} falling faster than {self._quantity(-high)}" if high < 0
                else f"{self.signal} not rising faster than {self._quantity(high)}")


def _rate_unit(unit: str, per_hour: bool) -> str:
    """Unit of a signal's rate: "°C" → "K/h", "m³/s" → "m³/s/h", "1" or "" → "/h" (or "/step")."""
    per = "/h" if per_hour else "/step"
    if not unit or unit == "1":
        return per
    return _RATE_UNITS.get(unit, unit) + per


class OperatingRegimes(BaseEstimator):
    """Mini-batch k-means operating regimes with decision-tree rules (see the module docstring).

    :param max_regimes: largest k tried by the silhouette criterion (k ≥ 2).
    :param n_regimes: fixed number of regimes (skips the criterion).
    :param smoothing_steps: odd moving-average window of the rate features, in steps.
    :param tree_depth: maximum depth of the rule tree.
    :param random_state: seed (int), ``numpy.random.RandomState`` or None.

    Fitted attributes: ``labels_`` (``ndarray[n_t]``, −1 for left-out steps), ``n_regimes_``,
    ``selection_scores_`` (k → mean silhouette), ``centers_`` (``ndarray[n_regimes, 2·n_f]``: the
    mean of each regime's steps, inputs then rates, in engineering units), ``signal_names_`` (the
    n_f inputs), ``feature_names_`` and ``feature_units_`` (of the 2·n_f columns), ``rules_``
    (``list[str]``, one per regime), ``rule_conditions_`` (per regime, per tree leaf, the
    :class:`RuleCondition` list), ``rule_accuracy_``, ``tree_``, ``step_s_``.
    """

    def __init__(self, max_regimes: int = 8, n_regimes: int | None = None, smoothing_steps: int = 5,
                 tree_depth: int = 3, random_state: int | np.random.RandomState | None = None):
        self.max_regimes = max_regimes
        self.n_regimes = n_regimes
        self.smoothing_steps = smoothing_steps
        self.tree_depth = tree_depth
        self.random_state = random_state

    def _augment(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(inputs and their rates ``ndarray[n_t, 2·n_f]``, mask of steps where all are finite)."""
        features = np.asarray(features, dtype=float)
        if features.ndim != 2 or features.shape[1] != len(self.signal_names_):
            raise ValueError(
                f"features have shape {features.shape}, expected (n_steps, {len(self.signal_names_)}) "
                f"with columns {self.signal_names_}")
        augmented = np.hstack([features, smoothed_rate(features, self.smoothing_steps, self.step_s_)])
        return augmented, np.isfinite(augmented).all(axis=1)

    def fit(self, features: np.ndarray, feature_names: Sequence[str], valid: np.ndarray | None = None, *,
            feature_units: Sequence[str] | None = None, step_s: float | None = None) -> OperatingRegimes:
        """Cluster the operating states and derive the rules.

        :param features: boundary inputs and commands, ``ndarray[n_t, n_f]`` in engineering units,
            equally spaced in time (NaN allowed: those steps are left out).
        :param feature_names: one readable name per column ("supply fan speed").
        :param valid: ``ndarray[n_t]`` of bool, steps to use (default all).
        :param feature_units: one unit label per column for the rules ("°C", "m³/s", "1" or "").
        :param step_s: step length in seconds: rates per hour when given, else per step.
        """
        if isinstance(feature_names, str) or (valid is not None and np.asarray(valid).dtype.kind not in "b"):
            raise TypeError("feature_names must be a list of names and valid a boolean array "
                            "(units go in the keyword feature_units)")
        self.signal_names_ = list(feature_names)
        units = list(feature_units) if feature_units is not None else [""] * len(self.signal_names_)
        if len(units) != len(self.signal_names_):
            raise ValueError(f"{len(units)} feature_units for {len(self.signal_names_)} feature_names")
        if self.max_regimes < 2 or (self.n_regimes is not None and self.n_regimes < 1):
            raise CalibrationError(
                f"max_regimes must be ≥ 2 and n_regimes ≥ 1, got {self.max_regimes}, {self.n_regimes}")
        self.step_s_ = step_s
        augmented, usable = self._augment(features)
        if valid is not None:
            valid = np.asarray(valid, dtype=bool)
            if valid.shape != usable.shape:
                raise ValueError(f"valid has shape {valid.shape}, expected ({len(usable)},)")
            usable &= valid
        self.feature_names_ = self.signal_names_ + [f"rate of {n}" for n in self.signal_names_]
        self.feature_units_ = units + [_rate_unit(u, step_s is not None) for u in units]
        data = augmented[usable]
        fewest = self.n_regimes if self.n_regimes is not None else 2
        if len(data) <= fewest:
            raise CalibrationError(f"only {len(data)} usable steps (finite inputs and rates, valid): "
                                   f"too few to find {fewest} operating regimes")
        k_max = min(self.max_regimes, len(data) - 1)

        rng = check_random_state(self.random_state)
        seed = int(rng.randint(np.iinfo(np.int32).max))
        scaled = self._standardise(data)
        sample = rng.choice(len(scaled), size=min(SILHOUETTE_SUBSAMPLE, len(scaled)), replace=False)
        candidates = [self.n_regimes] if self.n_regimes is not None else range(2, k_max + 1)
        self.selection_scores_: dict[int, float] = {}
        best: tuple[float, MiniBatchKMeans] | None = None
        for k in candidates:
            with threadpool_limits(limits=1, user_api="openmp"):
                kmeans = MiniBatchKMeans(n_clusters=k, random_state=seed, n_init=3, batch_size=1024).fit(scaled)
            labelled = kmeans.labels_[sample]
            score = float(silhouette_score(scaled[sample], labelled)) if len(np.unique(labelled)) > 1 else -1.0
            self.selection_scores_[k] = score
            if best is None or score > best[0]:
                best = (score, kmeans)
        kmeans = best[1]
        self.n_regimes_ = kmeans.n_clusters
        order = np.argsort(-np.bincount(kmeans.labels_, minlength=self.n_regimes_), kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        self.labels_ = np.full(len(usable), -1, dtype=int)
        self.labels_[usable] = rank[kmeans.labels_]
        self.centers_ = np.array([data[rank[kmeans.labels_] == r].mean(axis=0) for r in range(self.n_regimes_)])

        regime_labels = self.labels_[usable]
        self.tree_ = DecisionTreeClassifier(max_depth=self.tree_depth, random_state=seed).fit(data, regime_labels)
        smallest = int(np.bincount(regime_labels).min())
        folds = min(5, smallest)
        self.rule_accuracy_ = float(cross_val_score(
            DecisionTreeClassifier(max_depth=self.tree_depth, random_state=seed), data, regime_labels, cv=folds,
        ).mean()) if folds >= 2 else float("nan")
        low, high = np.percentile(data, [5, 95], axis=0)
        self._range_decimals = [_range_decimals(h - lo) for lo, h in zip(low, high)]
        self.rule_conditions_ = self._leaf_conditions()
        self.rules_ = [self._rule_text(leaves) for leaves in self.rule_conditions_]
        return self

    def _standardise(self, data: np.ndarray) -> np.ndarray:
        """Clustering coordinates of ``[inputs, rates]`` (``docs/calibration.md``, *Operating regimes*, Scaling)."""
        n_signals = len(self.signal_names_)
        levels, rates = data[:, :n_signals], data[:, n_signals:]
        spread = robust_spread(levels)
        window = self.smoothing_steps * (self.step_s_ / 3600.0 if self.step_s_ is not None else 1.0)
        scaled = np.hstack([(levels - np.median(levels, axis=0)) / spread, rates * window / spread])
        return np.clip(scaled, -Z_CLIP, Z_CLIP)

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Regime of each step of new data (``ndarray[n_t, n_f]``, same columns as in :meth:`fit`) by
        the rule tree; −1 where an input or its rate is not finite. The rates are computed on the
        new series itself, so pass a contiguous window."""
        check_is_fitted(self, "tree_")
        augmented, usable = self._augment(features)
        labels = np.full(len(usable), -1, dtype=int)
        if usable.any():
            labels[usable] = self.tree_.predict(augmented[usable])
        return labels

    def _leaf_conditions(self) -> list[list[list[RuleCondition]]]:
        tree = self.tree_.tree_
        classes = self.tree_.classes_

        def pure_regime(node: int) -> int | None:
            """The regime every leaf under ``node`` predicts, or None if they differ."""
            if tree.children_left[node] == tree.children_right[node]:
                return int(classes[np.argmax(tree.value[node][0])])
            left, right = pure_regime(tree.children_left[node]), pure_regime(tree.children_right[node])
            return left if left is not None and left == right else None

        leaves: list[list[list[RuleCondition]]] = [[] for _ in range(self.n_regimes_)]

        def walk(node: int, bounds: dict[int, tuple[float | None, float | None]]) -> None:
            regime = pure_regime(node)
            if regime is not None:
                leaves[regime].append([self._condition(f, lo, hi) for f, (lo, hi) in sorted(bounds.items())])
                return
            feature, threshold = int(tree.feature[node]), float(tree.threshold[node])
            lo, hi = bounds.get(feature, (None, None))
            walk(tree.children_left[node], bounds | {feature: (lo, threshold if hi is None else min(hi, threshold))})
            walk(tree.children_right[node], bounds | {feature: (threshold if lo is None else max(lo, threshold), hi)})

        walk(0, {})
        return [_merged_paths(paths, self._condition) for paths in leaves]

    def _condition(self, feature: int, lower: float | None, upper: float | None) -> RuleCondition:
        n_signals = len(self.signal_names_)
        return RuleCondition(
            feature=feature, signal=self.signal_names_[feature % n_signals], unit=self.feature_units_[feature],
            is_rate=feature >= n_signals, lower=lower, upper=upper, range_decimals=self._range_decimals[feature],
        )

    @staticmethod
    def _rule_text(leaves: list[list[RuleCondition]]) -> str:
        if not leaves:
            return "no leaf of the rule tree: a minority regime the rules merge into others"
        paths = [" and ".join(c.describe() for c in leaf) or "always" for leaf in leaves]
        return " or ".join(f"({p})" if len(leaves) > 1 and " and " in p else p for p in paths)


def _merged_paths(paths: list[list[RuleCondition]], condition) -> list[list[RuleCondition]]:
    """The rule tree's paths to one regime with any two that differ only in adjacent intervals of one
    feature joined (``A and x ≤ 29`` or ``A and x > 29`` is ``A``), until no two do; ``condition``
    makes a :class:`RuleCondition` of (feature, lower, upper)."""
    bounds = [{c.feature: (c.lower, c.upper) for c in path} for path in paths]
    joined = True
    while joined:
        joined = False
        for i, j in itertools.combinations(range(len(bounds)), 2):
            a, b = bounds[i], bounds[j]
            differing = [f for f in a.keys() | b.keys() if a.get(f) != b.get(f)]
            if len(differing) != 1:
                continue
            f = differing[0]
            (lo_a, hi_a), (lo_b, hi_b) = a.get(f, (None, None)), b.get(f, (None, None))
            if hi_a is not None and hi_a == lo_b:
                union = (lo_a, hi_b)
            elif hi_b is not None and hi_b == lo_a:
                union = (lo_b, hi_a)
            else:
                continue
            merged = {k: v for k, v in a.items() if k != f} | ({f: union} if union != (None, None) else {})
            bounds = [merged if k == i else path for k, path in enumerate(bounds) if k != j]
            joined = True
            break
    return [[condition(f, lo, hi) for f, (lo, hi) in sorted(path.items())] for path in bounds]


def per_regime_metrics(
    labels: np.ndarray,
    observed: np.ndarray,
    predicted: np.ndarray,
    metric_fns: Mapping[str, Callable[[np.ndarray, np.ndarray], float]],
    *,
    n_regimes: int | None = None,
) -> list[dict]:
    """Every metric per regime, with the regime's share of time.

    :param labels: ``ndarray[n_t]`` regime per step (−1: not labelled, left out of the shares).
    :param observed: ``ndarray[n_t]`` measured (NaN: no measurement).
    :param predicted: ``ndarray[n_t]`` model prediction.
    :param metric_fns: name → ``fn(y, ŷ) -> float``, called on the regime's steps where both are finite.
    :param n_regimes: report regimes 0 … n_regimes − 1 even if absent from ``labels`` (default: the
        regimes present).
    :returns: one dict per regime, ``{"regime", "share", "n_steps", "n_measured", <metric>: value}``;
        a metric is NaN where the regime has no measured step.
    """
    labels = np.asarray(labels)
    observed = np.asarray(observed, dtype=float)
    predicted = np.asarray(predicted, dtype=float)
    if not labels.shape == observed.shape == predicted.shape or labels.ndim != 1:
        raise ValueError(f"labels {labels.shape}, observed {observed.shape} and predicted {predicted.shape} "
                         "must be 1-D of the same length")
    labelled = labels >= 0
    regimes = range(n_regimes) if n_regimes is not None else np.unique(labels[labelled])
    both = np.isfinite(observed) & np.isfinite(predicted)
    rows = []
    for regime in regimes:
        in_regime = labels == regime
        measured = in_regime & both
        row = {"regime": int(regime), "share": float(in_regime.sum() / max(labelled.sum(), 1)),
               "n_steps": int(in_regime.sum()), "n_measured": int(measured.sum())}
        for name, fn in metric_fns.items():
            row[name] = float(fn(observed[measured], predicted[measured])) if measured.any() else float("nan")
        rows.append(row)
    return rows


def worst_regime(rows: Sequence[dict], metric: str, *, higher_is_worse: bool = True, min_share: float = 0.0) -> dict:
    """The row of :func:`per_regime_metrics` with the worst ``metric`` among regimes holding at least
    ``min_share`` of the time (NaN metrics ignored)."""
    eligible = [r for r in rows if r["share"] >= min_share and np.isfinite(r[metric])]
    if not eligible:
        raise CalibrationError(f"no regime with a finite {metric!r} and a share of time ≥ {min_share}")
    key = (lambda r: r[metric]) if higher_is_worse else (lambda r: -r[metric])
    return max(eligible, key=key)
