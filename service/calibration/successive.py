"""Successive (regime-by-regime) point calibration, and its comparison with the joint fit.

Method (RWTH Aachen, "calibration classes"): 1. screen: Morris μ* per operating regime of the
weighted RMS residual; 2. plan: each parameter to the regime where its μ* share is highest, regimes
with the most parameters first; 3. successive stages: per regime, its parameters fitted on its
measured steps only, the others held; 4. a joint fine-tuning of all parameters from that estimate.
:func:`compare_strategies` scores it against the joint fit per target and regime and by blocked
cross-validation (the weighted RMSE ``sqrt(mean_{k,t} ((y_k(t) − ŷ_k(t)) / s_k)²)`` of held-out
blocks, the training window's ``s_k``). Details: ``docs/calibration.md``, *Successive calibration*.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils import check_random_state

from service.calibration.metrics import target_metrics
from service.calibration.model_data import ModelData
from service.calibration.point import PointCalibrator
from service.calibration.problem import CalibrationProblem
from service.calibration.regime_breakdown import fit_boundary_regimes
from service.calibration.regime_sensitivity import (
    RegimeSensitivity,
    calibration_morris_by_regime,
    successive_calibration_plan,
)
from service.calibration.regimes import OperatingRegimes, per_regime_metrics
from service.calibration.run import predict_test
from service.data.model_series import read_model_data
from service.data.windows import Window
from service.errors import CalibrationError
from service.graph.store import GraphStore
from service.graph.units import difference_label
from service.model.assembly import assemble
from service.model.simulator import loop_substeps

__all__ = [
    "CalibrationStage", "SuccessiveCalibrator", "restricted_problem", "contiguous_folds", "cross_validate",
    "FoldScore", "boundary_regimes",
    "StrategyResult", "StrategyComparison", "compare_strategies", "compare_calibration_strategies", "STRATEGIES",
    "CV_TIE_SHARE",
]

STRATEGIES = ("joint", "successive")
#: Two fits whose every parameter agrees within this share (of the two values' mean) are one fit.
SAME_FIT_SHARE = 1e-3
#: Mean CV scores closer than this share of the lower are a tie: neither strategy generalises better.
CV_TIE_SHARE = 0.01


def restricted_problem(problem: CalibrationProblem, columns: Sequence[int], theta: np.ndarray,
                       steps: np.ndarray | None = None) -> CalibrationProblem:
    """``problem`` with only ``columns`` of θ free (the others held at ``theta``) and, when ``steps``
    (``bool[n_steps]``) is given, only those steps compared; targets without a measured step left
    there are dropped. The target scales stay those of ``problem``, so costs remain comparable.

    :raises CalibrationError: when no target has a measured step in ``steps``.
    """
    columns = np.asarray(columns, dtype=int)
    held = np.array(theta, dtype=float)
    observed = {k: (v if steps is None else np.where(steps, v, np.nan)) for k, v in problem.observed.items()}
    observed = {k: v for k, v in observed.items() if np.isfinite(v).any()}
    if not observed:
        raise CalibrationError("the restricted problem has no measured step: every target is NaN on the chosen steps")

    def simulate(free: np.ndarray) -> dict[str, np.ndarray]:
        full = np.repeat(held[None, :], len(free), axis=0)
        full[:, columns] = free
        return problem.simulate(full)

    return replace(
        problem, parameter_names=tuple(problem.parameter_names[j] for j in columns),
        lower=problem.lower[columns], upper=problem.upper[columns], simulate=simulate, observed=observed,
        units={k: problem.units[k] for k in observed}, target_scales={k: problem.target_scales[k] for k in observed},
        default=np.clip(held[columns], problem.lower[columns], problem.upper[columns]), gp_inputs=None,
    )


@dataclass(frozen=True)
class CalibrationStage:
    """One stage of a successive calibration: ``regime`` (None for the joint fine-tuning), the
    parameters it fitted and their ``estimates`` after it (physical units), its measured values, its
    cost ``½ Σ ((y − ŷ)/s)²`` on those values before and after, and its simulate calls."""

    regime: int | None
    parameters: tuple[str, ...]
    estimates: tuple[float, ...]
    n_measured: int
    cost_before: float
    cost_after: float
    n_simulate_calls: int

    def to_dict(self) -> dict:
        return {"regime": self.regime, "parameters": list(self.parameters), "estimates": list(self.estimates),
                "n_measured": self.n_measured, "cost_before": self.cost_before, "cost_after": self.cost_after,
                "n_simulate_calls": self.n_simulate_calls}


def _cost(problem: CalibrationProblem, theta: np.ndarray) -> float:
    """``½ Σ ((y − ŷ)/s)²`` over the problem's measured values for one θ."""
    return float(0.5 * np.sum(problem.weighted_residuals(problem.run(np.asarray(theta)[None, :])) ** 2))


class SuccessiveCalibrator(BaseEstimator):
    """Regime-by-regime point calibration with a joint fine-tuning (module docstring, steps 1–4).

    :param n_trajectories: Morris trajectories (``n_trajectories · (n_parameters + 1)`` members in
        one simulate call).
    :param num_levels: Morris grid levels.
    :param min_share: a parameter whose μ* share is below this in every regime gets no stage (it
        is still freed in the fine-tuning).
    :param n_starts, n_candidates, max_nfev: :class:`PointCalibrator` settings of every stage.
    :param fine_tune_candidates: Latin-hypercube points screened against the successive estimate
        before the fine-tuning's one local run.
    :param fine_tune_max_nfev: residual evaluations of the fine-tuning.
    :param random_state: seed (int), ``numpy.random.RandomState`` or None.

    Fitted: ``sensitivity_`` (:class:`RegimeSensitivity`), ``plan_`` (``[(regime, [names])]``),
    ``stages_`` (:class:`CalibrationStage` list, the fine-tuning last), ``theta_`` (physical units),
    ``point_calibrator_`` (the fine-tuning's :class:`PointCalibrator`: standard errors,
    identifiability, residuals, prediction), ``cost_`` (½ Σ weighted r² on all data),
    ``n_simulate_calls_`` (Morris, stages and fine-tuning).
    """

    def __init__(self, n_trajectories: int = 10, num_levels: int = 4, min_share: float = 0.02, n_starts: int = 2,
                 n_candidates: int = 32, max_nfev: int = 40, fine_tune_candidates: int = 1,
                 fine_tune_max_nfev: int = 20, random_state: int | np.random.RandomState | None = None) -> None:
        self.n_trajectories = n_trajectories
        self.num_levels = num_levels
        self.min_share = min_share
        self.n_starts = n_starts
        self.n_candidates = n_candidates
        self.max_nfev = max_nfev
        self.fine_tune_candidates = fine_tune_candidates
        self.fine_tune_max_nfev = fine_tune_max_nfev
        self.random_state = random_state

    def fit(self, problem: CalibrationProblem, labels: np.ndarray) -> SuccessiveCalibrator:
        """Screen, plan, fit regime by regime, fine-tune; returns ``self``.

        :param labels: ``ndarray[problem.n_steps]`` regime of each step (−1: in no regime; such
            steps only enter the fine-tuning).
        """
        labels = np.asarray(labels)
        if labels.shape != (problem.n_steps,):
            raise ValueError(f"labels have shape {labels.shape}, expected ({problem.n_steps},): one per problem step")
        rng = check_random_state(self.random_state)
        seed = lambda: int(rng.randint(np.iinfo(np.int32).max))  # noqa: E731
        self.sensitivity_ = calibration_morris_by_regime(
            problem, labels, n_trajectories=self.n_trajectories, num_levels=self.num_levels, seed=seed())
        self.plan_ = successive_calibration_plan(self.sensitivity_, min_share=self.min_share)
        self.n_simulate_calls_ = 1
        names = list(problem.parameter_names)
        theta = problem.default.copy() if problem.default is not None else 0.5 * (problem.lower + problem.upper)
        self.stages_: list[CalibrationStage] = []
        for regime, stage_names in self.plan_:
            stage = restricted_problem(problem, [names.index(n) for n in stage_names], theta, labels == regime)
            if stage.n_observations <= len(stage_names):  # too few steps of the regime here: left to the fine-tuning
                continue
            before = _cost(stage, stage.default)
            fitted = PointCalibrator(n_starts=self.n_starts, n_candidates=self.n_candidates, random_state=seed(),
                                     max_nfev=self.max_nfev).fit(stage)
            theta[[names.index(n) for n in stage_names]] = fitted.theta_
            self.stages_.append(CalibrationStage(regime, tuple(stage_names), tuple(map(float, fitted.theta_)),
                                                 stage.n_observations, before, fitted.cost_,
                                                 fitted.n_simulate_calls_ + 1))
            self.n_simulate_calls_ += fitted.n_simulate_calls_ + 1
        whole = replace(problem, default=theta)
        before = _cost(whole, theta)
        fine = self.point_calibrator_ = PointCalibrator(
            n_starts=1, n_candidates=self.fine_tune_candidates, random_state=seed(), max_nfev=self.fine_tune_max_nfev,
        ).fit(whole)
        self.stages_.append(CalibrationStage(None, tuple(names), tuple(map(float, fine.theta_)), whole.n_observations,
                                             before, fine.cost_, fine.n_simulate_calls_ + 1))
        self.n_simulate_calls_ += fine.n_simulate_calls_ + 1
        self.theta_ = self.point_calibrator_.theta_
        self.cost_ = self.point_calibrator_.cost_
        return self


def _fold_min_steps(model_data: ModelData, window: slice, settling_s: float | None) -> int:
    """Shortest block a fold may have: its unscored start (the first block's, the longest) and two
    steps to score."""
    return model_data.unscored_start_steps(window, settling_s) + 2


def contiguous_folds(window: slice, n_folds: int, *, min_steps: int = 1) -> list[tuple[list[slice], slice]]:
    """Blocked cross-validation of ``window``: ``n_folds`` contiguous blocks of (nearly) equal
    length; fold i holds out block i and fits on the blocks before and after it (one slice each,
    each simulated on its own). Returns ``[(fit windows, held-out block)]``.

    :param min_steps: the shortest block allowed (e.g. the warm-up plus a few compared steps).
    :raises CalibrationError: for fewer than 2 folds or blocks shorter than ``min_steps``.
    """
    start, stop = window.start or 0, window.stop
    if n_folds < 2:
        raise CalibrationError(f"cross-validation needs n_folds ≥ 2, got {n_folds}")
    edges = np.linspace(start, stop, n_folds + 1).round().astype(int)
    if np.diff(edges).min() < min_steps:
        raise CalibrationError(f"{n_folds} folds of a {stop - start}-step window give blocks of {np.diff(edges).min()} "
                               f"steps, fewer than the {min_steps} needed (warm-up plus compared steps)")
    folds = []
    for i in range(n_folds):
        held_out = slice(int(edges[i]), int(edges[i + 1]))
        fit = [s for s in (slice(start, held_out.start), slice(held_out.stop, stop)) if s.stop > s.start]
        folds.append((fit, held_out))
    return folds


def boundary_regimes(model_data: ModelData, window: slice, *, seed: int = 0,
                     **options) -> tuple[OperatingRegimes, np.ndarray]:
    """Operating regimes from the model's boundary inputs on ``window`` (names and units as
    the diagnosis uses them), and their labels for every step of the data (−1 where an input is
    missing). ``options`` go to :class:`OperatingRegimes`."""
    regimes, features = fit_boundary_regimes(model_data, window, seed=seed, **options)
    return regimes, regimes.predict(features)


@dataclass(frozen=True)
class FoldScore:
    """One fold of the blocked cross-validation: the windows fitted on, the held-out block, the
    estimate θ of the fit windows, its weighted RMSE on the held-out block and the RMSE per target
    there (target's unit)."""

    fit_windows: tuple[slice, ...]
    held_out: slice
    theta: np.ndarray
    weighted_rmse: float
    rmse: dict[str, float]

    def to_dict(self) -> dict:
        return {"fit": [[w.start, w.stop] for w in self.fit_windows],
                "held_out": [self.held_out.start, self.held_out.stop], "theta": self.theta.tolist(),
                "weighted_rmse": self.weighted_rmse, "rmse": self.rmse}


def cross_validate(
    model_data: ModelData,
    window: slice,
    labels: np.ndarray,
    *,
    strategy: str,
    n_folds: int = 3,
    target_scales: dict[str, float] | None = None,
    seed: int = 0,
    settling_s: float | None = None,
    n_starts: int = 2,
    n_candidates: int = 32,
    max_nfev: int = 40,
) -> list[FoldScore]:
    """Blocked cross-validation of one strategy on ``window`` (:func:`contiguous_folds`): fit on the
    other blocks (each simulated on its own), simulate the held-out block on its own and score it
    after its first ``settling_s``.

    :param labels: ``ndarray[n_data_steps]`` regime of every data step (the successive strategy's
        Morris and plan are redone on each fold's fit windows).
    :param target_scales: the residual scales (default: those of the whole ``window``), the same
        for every fold so the scores compare.
    :param n_starts, n_candidates, max_nfev: :class:`PointCalibrator` settings, as in
        :func:`compare_strategies`.
    """
    if strategy not in STRATEGIES:
        raise CalibrationError(f"unknown strategy {strategy!r}: use one of {', '.join(STRATEGIES)}")
    settings = {"n_starts": n_starts, "n_candidates": n_candidates, "max_nfev": max_nfev}
    scales = dict(target_scales or model_data.problem(window, settling_s=settling_s).target_scales)
    scores = []
    for fit_windows, held_out in contiguous_folds(window, n_folds, min_steps=_fold_min_steps(model_data, window, settling_s)):
        fit_problem = model_data.problem(fit_windows, target_scales=scales, settling_s=settling_s)
        fit_labels = np.concatenate([labels[w] for w in fit_windows])
        theta = _fit(strategy, fit_problem, fit_labels, settings, seed).theta_
        held_problem = model_data.problem(held_out, target_scales=scales, settling_s=settling_s)
        outputs = held_problem.run(theta[None, :])
        residuals = held_problem.weighted_residuals(outputs)[0]
        scores.append(FoldScore(
            tuple(fit_windows), held_out, theta, float(np.sqrt(np.mean(residuals**2))),
            {k: target_metrics(v, outputs[k][0]).rmse for k, v in held_problem.observed.items()}))
    return scores


@dataclass
class StrategyResult:
    """One strategy's fit (see :func:`compare_strategies`).

    ``regime_metrics[window]`` (``"train"``, ``"test"``) is a list per regime of ``{"regime",
    "share", "n_steps", "rmse": {target: value}, "r2": {target: value}, "n_measured": {target: n}}``;
    ``cv`` the :class:`FoldScore` per fold; ``estimates`` name → ``{"value", "standard_error", "identified"}``.
    """

    strategy: str
    theta: np.ndarray
    estimates: dict[str, dict]
    cost: float
    n_simulate_calls: int
    regime_metrics: dict[str, list[dict]]
    cv: list[FoldScore] = field(default_factory=list)
    stages: list[CalibrationStage] = field(default_factory=list)

    @property
    def cv_scores(self) -> list[float]:
        """Weighted RMSE on each held-out block."""
        return [fold.weighted_rmse for fold in self.cv]

    @property
    def cv_mean(self) -> float:
        return float(np.mean(self.cv_scores)) if self.cv_scores else float("nan")

    def to_dict(self) -> dict:
        return {"strategy": self.strategy, "theta": self.theta.tolist(), "estimates": self.estimates,
                "cost": self.cost, "n_simulate_calls": self.n_simulate_calls, "regime_metrics": self.regime_metrics,
                "cv_scores": self.cv_scores, "cv_mean": self.cv_mean, "cv": [f.to_dict() for f in self.cv],
                "stages": [s.to_dict() for s in self.stages]}


@dataclass
class StrategyComparison:
    """Joint and successive fits side by side: ``strategies`` (name → :class:`StrategyResult`),
    the training window's Morris table ``sensitivity`` and ``plan``, the regime ``rules`` and the
    target ``units``."""

    strategies: dict[str, StrategyResult]
    sensitivity: RegimeSensitivity
    plan: list[tuple[int, list[str]]]
    rules: list[str]
    units: dict[str, str]

    @property
    def better(self) -> str:
        """``"joint"`` or ``"successive"``, the lower mean CV score, or ``"tie"`` when the two differ
        by less than :data:`CV_TIE_SHARE` of the lower (or there is no cross-validation)."""
        joint, successive = (self.strategies[s].cv_mean for s in STRATEGIES)
        if not (np.isfinite(joint) and np.isfinite(successive)) or abs(joint - successive) < CV_TIE_SHARE * min(
                joint, successive):
            return "tie"
        return "joint" if joint < successive else "successive"

    def table(self) -> str:
        """Readable side-by-side table: per target and regime RMSE and R², then the CV scores."""
        joint, successive = self.strategies["joint"], self.strategies["successive"]
        lines = []
        for window in joint.regime_metrics:
            lines.append(f"{window} window: RMSE (R²) per regime, joint | successive")
            for j_row, s_row in zip(joint.regime_metrics[window], successive.regime_metrics[window]):
                rule = self.rules[j_row["regime"]] if j_row["regime"] < len(self.rules) else ""
                lines.append(f" regime {j_row['regime']} ({100 * j_row['share']:.0f} %): {rule}")
                for target in j_row["rmse"]:
                    name = target.replace("#", "/").rsplit("/", 1)[-1]
                    lines.append(f"   {name:<42} {j_row['rmse'][target]:>9.4g} ({j_row['r2'][target]:>6.3f})"
                                 f" | {s_row['rmse'][target]:>9.4g} ({s_row['r2'][target]:>6.3f})"
                                 f"  {difference_label(self.units[target])}")
        lines.append(f"cross-validation on {len(joint.cv)} held-out blocks (weighted RMSE, lower is better)")
        for name in STRATEGIES:
            result = self.strategies[name]
            folds = "  ".join(f"{v:.3f}" for v in result.cv_scores)
            lines.append(f" {name:<11} {folds}   mean {result.cv_mean:.4g}   cost {result.cost:.4g}"
                         f"   {result.n_simulate_calls} simulate calls")
        lines.append(f"better on held-out data: {self.better}")
        if self.better == "tie" and joint.theta.size:
            apart = float(np.max(2.0 * np.abs(joint.theta - successive.theta)
                                 / np.maximum(np.abs(joint.theta) + np.abs(successive.theta), 1e-300)))
            lines.append(f" both ended at the same parameters (at most {100 * apart:.2g} % apart): the regimes' stages "
                         "reach the joint fit's optimum" if apart < SAME_FIT_SHARE else
                         f" at different parameters (up to {100 * apart:.0f} % apart) with the same held-out error: "
                         "these data do not tell the two fits apart")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"strategies": {k: v.to_dict() for k, v in self.strategies.items()},
                "better": self.better, "rules": self.rules, "plan": [[r, names] for r, names in self.plan],
                "sensitivity": self.sensitivity.to_dict()}


def _regime_metrics(labels: np.ndarray, observed: dict[str, np.ndarray], predicted: dict[str, np.ndarray],
                    n_regimes: int) -> list[dict]:
    """RMSE and R² per regime and target on the steps where both are finite."""
    fns = {"rmse": lambda y, yhat: target_metrics(y, yhat).rmse, "r2": lambda y, yhat: target_metrics(y, yhat).r2}
    rows = [{"regime": r, "rmse": {}, "r2": {}, "n_measured": {}} for r in range(n_regimes)]
    for target, values in observed.items():
        for row in per_regime_metrics(labels, values, predicted[target], fns, n_regimes=n_regimes):
            out = rows[row["regime"]]
            out.update(share=row["share"], n_steps=row["n_steps"])
            out["rmse"][target], out["r2"][target] = row["rmse"], row["r2"]
            out["n_measured"][target] = row["n_measured"]
    return rows


def _fit(strategy: str, problem: CalibrationProblem, labels: np.ndarray, settings: dict,
         seed: int) -> PointCalibrator | SuccessiveCalibrator:
    """The fitted joint :class:`PointCalibrator` or :class:`SuccessiveCalibrator`."""
    if strategy == "joint":
        return PointCalibrator(random_state=seed, **settings).fit(problem)
    return SuccessiveCalibrator(random_state=seed, fine_tune_max_nfev=settings["max_nfev"], **settings).fit(
        problem, labels)


def compare_strategies(
    model_data: ModelData,
    train: slice,
    labels: np.ndarray,
    *,
    test: slice | None = None,
    rules: Sequence[str] = (),
    n_folds: int = 3,
    seed: int = 0,
    settling_s: float | None = None,
    n_starts: int = 2,
    n_candidates: int = 32,
    max_nfev: int = 40,
) -> StrategyComparison:
    """Fit the joint and the successive strategy on ``train``, score them per regime and by blocked
    cross-validation (module docstring).

    :param labels: ``ndarray[n_data_steps]`` regime of every step of the data (−1: none), e.g. from
        :func:`boundary_regimes`.
    :param rules: the regimes' rules in words (for the table).
    :param n_folds: held-out blocks of the training window (0: no cross-validation).
    :param n_starts, n_candidates, max_nfev: :class:`PointCalibrator` settings of the joint fit and
        of every successive stage; the fine-tuning gets the same ``max_nfev``.
    """
    labels = np.asarray(labels)
    if labels.shape != (len(model_data.data.timestamps),):
        raise ValueError(f"labels have shape {labels.shape}, expected ({len(model_data.data.timestamps)},): "
                         "one per data step")
    n_regimes = int(labels.max()) + 1 if (labels >= 0).any() else 0
    settings = {"n_starts": n_starts, "n_candidates": n_candidates, "max_nfev": max_nfev}
    if n_folds:  # refuse impossible folds before any fit
        contiguous_folds(train, n_folds, min_steps=_fold_min_steps(model_data, train, settling_s))
    problem = model_data.problem(train, settling_s=settling_s)

    strategies, fitted = {}, {}
    for name in STRATEGIES:
        fitted[name] = estimator = _fit(name, problem, labels[train], settings, seed)
        theta = estimator.theta_
        calibrator = estimator.point_calibrator_ if name == "successive" else estimator
        metrics = {"train": _regime_metrics(labels[train], dict(problem.observed),
                                            {k: v[0] for k, v in problem.run(theta[None, :]).items()}, n_regimes)}
        if test is not None:
            predicted = predict_test(model_data, train, test, theta, settling_s)
            observed = {k: np.where(np.isfinite(predicted[k]), v, np.nan) for k, v in model_data.observed(test).items()}
            metrics["test"] = _regime_metrics(labels[test], observed, predicted, n_regimes)
        estimates = {
            key: {"value": float(theta[j]), "standard_error": float(calibrator.standard_errors_[j]),
                  "identified": bool(calibrator.identifiability_[key].identified)}
            for j, key in enumerate(problem.parameter_names)
        }
        folds = cross_validate(model_data, train, labels, strategy=name, n_folds=n_folds,
                               target_scales=problem.target_scales, seed=seed, settling_s=settling_s,
                               **settings) if n_folds else []
        strategies[name] = StrategyResult(name, theta, estimates, estimator.cost_, estimator.n_simulate_calls_,
                                          metrics, cv=folds, stages=getattr(estimator, "stages_", []))

    successive = fitted["successive"]
    return StrategyComparison(strategies, successive.sensitivity_, successive.plan_, list(rules),
                              dict(model_data.units))


def compare_calibration_strategies(
    store: GraphStore,
    model_name: str,
    data_path: Path | str,
    *,
    train: Window,
    test: Window | None = None,
    n_folds: int = 3,
    seed: int = 0,
    substeps: int | None = None,
) -> StrategyComparison:
    """:func:`compare_strategies` for a model in the store and a measurement CSV (what
    ``graphtwin compare-strategies`` runs): the regimes are those of the boundary inputs on the
    training window (:func:`boundary_regimes`). Nothing is written to the store.

    :raises InputError: a bad window, a target without measurements, too short a window for the folds.
    """
    model = assemble(store, model_name)
    data = read_model_data(model, data_path)
    model_data = ModelData(model, data, substeps or loop_substeps(model, data.step_s))
    train_slice = data.window(*train, label="training window")
    test_slice = data.window(*test, label="test window") if test is not None else None
    regimes, labels = boundary_regimes(model_data, train_slice, seed=seed)
    return compare_strategies(model_data, train_slice, labels, test=test_slice, rules=regimes.rules_,
                              n_folds=n_folds, seed=seed)
