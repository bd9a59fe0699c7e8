"""The ventilation case study with a known truth (issue 4's acceptance): synthetic data, the model
bound to it, training and test windows, the Bayesian fit and its test-window metrics. Shared by
``test_bayesian_acceptance.py`` and ``coverage_study.py``."""

from __future__ import annotations

import numpy as np
from case_study import EX, case_study_data

from service.calibration.bayesian import BayesianCalibrator
from service.calibration.metrics import target_metrics
from service.calibration.model_data import ModelData
from service.calibration.run import continuation
from service.data.model_series import read_model_data
from service.model.assembly import assemble
from service.model.simulator import loop_substeps

TRAIN = ("2026-01-12", "2026-01-12T23:59")
TEST = ("2026-01-13", None)
#: Settings of the Bayesian runs: ``graphtwin calibrate --method bayes`` (4 temperatures, 60 walkers,
#: IAT checked every 100 steps, the default moves), capped at 6,000 steps (they converge in about
#: 2,600 with the warm-up: about 8 minutes each on one core).
BAYES = dict(n_temperatures=4, max_steps=6000, check_interval=100, random_state=0, progress=False)
STRUCTURALLY_UNIDENTIFIABLE = ("supply_fan#c1", "supply_fan#c2", "supply_fan#c3", "supply_fan#c4",
                               "heating_coil_air_side#loop_flow_coefficient")


class CaseStudyTruth:
    """Synthetic data of the case study (optionally with a hidden effect), the model bound to it,
    the training problem and the continuation problem (training start to test end)."""

    def __init__(self, folder, hidden_effect: str | None = None, seed: int = 3):
        path = folder / f"case-{hidden_effect}-{seed}.csv"
        self.store, self.truth = case_study_data(path, seed=seed, n_days=2.0, hidden_effect=hidden_effect)
        model = assemble(self.store, "case")
        data = read_model_data(model, path)
        self.md = ModelData(model, data, loop_substeps(model, data.step_s))
        self.train = data.window(*TRAIN)
        self.test = data.window(*TEST)
        self.problem = self.md.problem(self.train)
        self.names = self.problem.parameter_names
        self.true_theta = np.array([self.truth.theta.get(k, np.nan) for k in self.names])

    def inside_68(self, fit: BayesianCalibrator) -> np.ndarray:
        """Per parameter: whether the truth lies inside the fit's 16–84 % posterior interval."""
        return (fit.quantile16_ <= self.true_theta) & (self.true_theta <= fit.quantile84_)

    def short(self, key: str) -> str:
        return key.rsplit("/", 1)[-1]

    def bayes(self) -> tuple[BayesianCalibrator, dict]:
        """Bayesian fit on the training day and test-window metrics of its posterior predictive."""
        fit = BayesianCalibrator(**BAYES).fit(self.problem)
        joined = continuation(self.train, self.test)
        offset = self.test.start - joined.start
        predictive = fit.predict(self.md.problem(joined, target_scales=self.problem.target_scales, settling_s=0.0))
        observed = self.md.observed(self.test)
        metrics = {
            node: target_metrics(
                observed[node], predictive.median[node][offset:], n_parameters=self.problem.n_parameters,
                intervals={level: tuple(b[offset:] for b in predictive.interval(node, level)) for level in (0.68, 0.9)},
                unit=self.problem.units[node], target=node,
            )
            for node in observed
        }
        return fit, metrics


def identifiable(point, problem) -> list[int]:
    """Indices of the parameters the point fit identifies to within ±5 % (95 % interval; module docstring)."""
    return [
        j for j, name in enumerate(problem.parameter_names)
        if point.identifiability_[name].identified and 1.96 * point.standard_errors_[j] <= 0.05 * abs(point.theta_[j])
    ]


def ace_at_90(metrics: dict) -> dict[str, float]:
    """Sensor (local name) → the test window's ACE of the 90 % prediction interval."""
    return {node.removeprefix(EX): next(c.ace for c in m.coverage if c.level == 0.9) for node, m in metrics.items()}
