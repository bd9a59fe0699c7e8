"""The test-window error of a calibrated model per operating regime.

:class:`~service.calibration.regimes.OperatingRegimes` fitted on the model's boundary inputs over the
whole data file (so the rules do not depend on where the test window was cut, and the versions of a
model calibrated on the same data get the same regimes), applied to the test window by the rule
tree. Per regime: its rule, its share of the test window's labelled steps, and every target's RMSE
on its measured steps (NaN where none). Every calibration with a test window writes it with the run
(``gt:OperatingRegime``, ``gt:Metric`` with ``gt:inRegime``): ``graphtwin history`` compares it
across model versions, ``diagnose`` names the worst regime.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from service.calibration.model_data import ModelData
from service.calibration.regimes import OperatingRegimes, per_regime_metrics
from service.graph.units import convert, unit_label

__all__ = ["RegimeBreakdown", "regime_breakdown", "fit_boundary_regimes"]


def fit_boundary_regimes(md: ModelData, window: slice, *, seed: int = 0,
                         **options) -> tuple[OperatingRegimes, np.ndarray]:
    """:class:`OperatingRegimes` fitted on ``md``'s boundary inputs over ``window`` (named by the
    device's local name, each in its CSV column's unit, so a rule reads as the data do and as
    ``--only-when`` takes it: a fan speed logged in % is "≤ 11 %", not "≤ 0.11"; ``options`` go to
    the estimator), and those inputs over the whole data, ``ndarray[n_data_steps, n_inputs]``, to
    label any steps with."""
    data = md.data
    nodes = [md.node_of[c] for c in md.model.boundary_inputs]
    logged = [data.source_units.get(n, data.units[n]) for n in nodes]
    features = np.column_stack([convert(data.series[n], data.units[n], unit) for n, unit in zip(nodes, logged)])
    names = [n.replace("#", "/").rsplit("/", 1)[-1].replace("_", " ") for n in nodes]
    regimes = OperatingRegimes(random_state=seed, **options).fit(
        features[window], names, feature_units=[unit_label(unit) for unit in logged], step_s=data.step_s)
    return regimes, features


def _rmse(y: np.ndarray, yhat: np.ndarray) -> float:
    return float(np.sqrt(np.mean((y - yhat) ** 2)))


@dataclass
class RegimeBreakdown:
    """``rules[i]``, ``shares[i]`` (of the test window's labelled steps) and ``rmse[i]`` (target node
    → RMSE in its unit) of regime ``i``; ``rule_accuracy`` is the rule tree's cross-validated
    accuracy."""

    rules: list[str]
    shares: list[float]
    rmse: list[dict[str, float]]
    rule_accuracy: float

    def rows(self) -> list[dict]:
        """One dict per regime: ``{"regime", "rule", "share", "rmse": {node: value}}``."""
        return [{"regime": i, "rule": rule, "share": share, "rmse": dict(rmse)}
                for i, (rule, share, rmse) in enumerate(zip(self.rules, self.shares, self.rmse))]


def regime_breakdown(md: ModelData, test: slice, observed: Mapping[str, np.ndarray],
                     predicted: Mapping[str, np.ndarray], *, seed: int = 0) -> RegimeBreakdown:
    """Regimes of ``md``'s boundary inputs and every target's RMSE per regime on ``test``.

    :param observed: target node → ``ndarray[n_test]`` measured (NaN: not compared).
    :param predicted: target node → ``ndarray[n_test]`` model prediction on the same steps.
    """
    regimes, features = fit_boundary_regimes(md, slice(None), seed=seed)
    labels = regimes.predict(features[test])
    labelled = labels >= 0
    shares = [float(np.mean(labels[labelled] == r)) if labelled.any() else 0.0 for r in range(regimes.n_regimes_)]
    rmse: list[dict[str, float]] = [{} for _ in range(regimes.n_regimes_)]
    for node in observed:
        for row in per_regime_metrics(labels, observed[node], predicted[node], {"rmse": _rmse},
                                      n_regimes=regimes.n_regimes_):
            rmse[row["regime"]][node] = row["rmse"]
    return RegimeBreakdown(list(regimes.rules_), shares, rmse, float(regimes.rule_accuracy_))
