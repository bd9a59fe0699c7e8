"""Operating regimes: clusters of operating states with rules an engineer can read (RWTH method).

Features are the boundary inputs and commands plus their smoothed first derivatives (a centred
moving average over ``smoothing_steps``, then the difference per hour), so ramps separate from steady
states. Each feature is robustly standardised (median, 1.4826·MAD; the standard deviation where the
MAD is 0) before clustering with scikit-learn's :class:`~sklearn.cluster.MiniBatchKMeans`.

The number of regimes, unless given, maximises the silhouette score (on a seeded subsample of at
most 2,000 steps) over k = 2 … ``max_regimes``. A shallow :class:`~sklearn.tree.DecisionTreeClassifier`
(depth ≤ ``tree_depth``) trained on the *unscaled* features reproduces the clusters; its 5-fold
cross-validated accuracy is ``rule_accuracy_`` and its paths, merged per regime, are ``rules_``
("supply air flow > 1.1 m³/s and outdoor air temperature ≤ 6.2 °C"). New data is mapped to regimes
by the tree (:meth:`OperatingRegimes.predict`): the rule a user reads is the rule that is applied.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.cluster import MiniBatchKMeans
from sklearn.metrics import silhouette_score
from sklearn.model_selection import cross_val_score
from sklearn.tree import DecisionTreeClassifier

__all__ = ["OperatingRegimes", "derivative_features", "per_regime_metrics"]


def derivative_features(values: np.ndarray, step_s: float, smoothing_steps: int) -> np.ndarray:
    """Centred moving average over ``smoothing_steps``, then its gradient per hour, per column."""
    values = np.asarray(values, dtype=float)
    kernel = np.ones(max(int(smoothing_steps), 1)) / max(int(smoothing_steps), 1)
    out = np.empty_like(values)
    for j in range(values.shape[1]):
        padded = np.pad(values[:, j], (kernel.size // 2, kernel.size - 1 - kernel.size // 2), mode="edge")
        smooth = np.convolve(padded, kernel, mode="valid")
        out[:, j] = np.gradient(smooth) * 3600.0 / step_s
    return out


def _robust_scale(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    center = np.median(features, axis=0)
    spread = 1.4826 * np.median(np.abs(features - center), axis=0)
    fallback = features.std(axis=0)
    spread = np.where(spread > 0, spread, np.where(fallback > 0, fallback, 1.0))
    return center, spread


def _format(value: float) -> str:
    magnitude = abs(value)
    digits = 3 if magnitude < 1 else 2 if magnitude < 10 else 1 if magnitude < 100 else 0
    return f"{value:.{digits}f}"


class OperatingRegimes(BaseEstimator):
    """Mini-batch k-means regimes with decision-tree rules (module docstring).

    :param max_regimes: largest k tried by the silhouette criterion.
    :param n_regimes: fixed k (skips the criterion).
    :param smoothing_steps: moving-average window of the derivative features.
    :param tree_depth: depth of the rule tree.
    :param random_state: seed.

    After :meth:`fit`: ``labels_``, ``n_regimes_``, ``selection_scores_`` (k → silhouette),
    ``centers_`` (``ndarray[k, n_features]``, engineering units), ``feature_names_``, ``rules_``
    (regime → text), ``rule_accuracy_``, ``tree_``.
    """

    def __init__(self, max_regimes: int = 6, n_regimes: int | None = None, smoothing_steps: int = 6,
                 tree_depth: int = 3, random_state: int | None = 0):
        self.max_regimes = max_regimes
        self.n_regimes = n_regimes
        self.smoothing_steps = smoothing_steps
        self.tree_depth = tree_depth
        self.random_state = random_state

    def features(self, signals: np.ndarray, names: Sequence[str], units: Sequence[str], step_s: float):
        """Signals plus derivatives: ``(ndarray[n_t, 2·n_signals], names, units)``."""
        signals = np.asarray(signals, dtype=float)
        derivatives = derivative_features(signals, step_s, self.smoothing_steps)
        return (
            np.hstack([signals, derivatives]),
            list(names) + [f"change of {n}" for n in names],
            list(units) + [f"{u}/h" for u in units],
        )

    def fit(self, features: np.ndarray, feature_names: Sequence[str], feature_units: Sequence[str] | None = None):
        """Cluster ``features`` (``ndarray[n_t, n_f]``, NaN-free) and derive the rules."""
        features = np.asarray(features, dtype=float)
        if features.ndim != 2 or features.shape[1] != len(feature_names):
            raise ValueError(f"features have shape {features.shape}, expected (n_steps, {len(feature_names)})")
        if not np.isfinite(features).all():
            raise ValueError("features contain NaN or infinite values: fill or drop those steps first")
        self.feature_names_ = list(feature_names)
        self.feature_units_ = list(feature_units) if feature_units is not None else [""] * len(feature_names)
        center, spread = _robust_scale(features)
        scaled = (features - center) / spread
        rng = np.random.default_rng(self.random_state)
        sample = rng.choice(len(scaled), size=min(2000, len(scaled)), replace=False)
        self.selection_scores_: dict[int, float] = {}
        candidates = [self.n_regimes] if self.n_regimes else range(2, max(self.max_regimes, 2) + 1)
        best = None
        for k in candidates:
            km = MiniBatchKMeans(n_clusters=k, random_state=self.random_state, n_init=3, batch_size=1024).fit(scaled)
            labels = km.labels_
            if len(np.unique(labels[sample])) < 2:
                score = -1.0
            else:
                score = float(silhouette_score(scaled[sample], labels[sample]))
            self.selection_scores_[k] = score
            if best is None or score > best[0]:
                best = (score, k, km)
        _, self.n_regimes_, kmeans = best
        order = np.argsort(-np.bincount(kmeans.labels_, minlength=self.n_regimes_))
        relabel = np.empty_like(order)
        relabel[order] = np.arange(order.size)
        self.labels_ = relabel[kmeans.labels_]
        self.centers_ = (kmeans.cluster_centers_ * spread + center)[order]
        self.tree_ = DecisionTreeClassifier(max_depth=self.tree_depth, random_state=self.random_state)
        self.tree_.fit(features, self.labels_)
        folds = min(5, int(np.bincount(self.labels_).min())) if self.n_regimes_ > 1 else 0
        self.rule_accuracy_ = (float(cross_val_score(
            DecisionTreeClassifier(max_depth=self.tree_depth, random_state=self.random_state),
            features, self.labels_, cv=folds).mean()) if folds >= 2 else float("nan"))
        self.rules_ = self._rules()
        return self

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Regime of each step of new data, by the rule tree."""
        return self.tree_.predict(np.asarray(features, dtype=float))

    def _rules(self) -> dict[int, str]:
        tree = self.tree_.tree_
        paths: dict[int, list[str]] = defaultdict(list)

        def walk(node: int, conditions: list[str]) -> None:
            if tree.children_left[node] == tree.children_right[node]:
                regime = int(self.tree_.classes_[np.argmax(tree.value[node][0])])
                paths[regime].append(" and ".join(conditions) or "always")
                return
            name = self.feature_names_[tree.feature[node]]
            unit = self.feature_units_[tree.feature[node]]
            threshold = _format(tree.threshold[node]) + (f" {unit}" if unit and unit != "1" else "")
            walk(tree.children_left[node], conditions + [f"{name} ≤ {threshold}"])
            walk(tree.children_right[node], conditions + [f"{name} > {threshold}"])

        walk(0, [])
        return {r: " or ".join(f"({p})" if len(paths[r]) > 1 else p for p in paths[r]) if r in paths
                else "(no leaf of the rule tree: a minority regime the rules merge into others)"
                for r in range(self.n_regimes_)}


def per_regime_metrics(
    labels: np.ndarray,
    observed: Mapping[str, np.ndarray],
    predicted: Mapping[str, np.ndarray],
    metric: Callable[[np.ndarray, np.ndarray], float],
) -> list[dict]:
    """For every regime: its share of the steps and ``metric(y, ŷ)`` per target (measured steps only)."""
    results = []
    for regime in np.unique(labels):
        mask = labels == regime
        row = {"regime": int(regime), "share": float(mask.mean()), "metric": {}}
        for key, values in observed.items():
            finite = mask & np.isfinite(values)
            row["metric"][key] = float(metric(values[finite], predicted[key][finite])) if finite.sum() else float("nan")
        results.append(row)
    return results
