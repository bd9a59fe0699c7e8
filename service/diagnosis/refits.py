"""A candidate's refits: what a worker gets (:class:`CandidateJob`), the probe of the effect's
parameters that starts each refit, and the least squares of the two hypotheses' fits (present
throughout: :mod:`service.diagnosis.candidates`; appearing in the test window: :func:`fit_onset`).
The method: ``docs/diagnosis.md``, "What is missing".
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from service.calibration.lockstep import with_prefetched_rows
from service.calibration.metrics import effective_sample_fraction
from service.calibration.model_data import ModelData
from service.calibration.point import PointCalibrator
from service.calibration.problem import CalibrationProblem
from service.data.measurements import MeasuredData
from service.diagnosis.drift import drift_identity
from service.diagnosis.ranking import residual_step_errors
from service.matching.signature import Signature
from service.model.assembled_model import AssembledModel

__all__ = [
    "PROBE_SHARES", "REFIT_CONTINUATIONS", "CandidateJob", "Fit", "fit_onset", "host_columns", "mean_squares",
    "null_values", "probe_ensemble", "probe_start", "refit_calibrator", "sample_fractions",
]

#: A refit stops where a step lowers its cost by less than this share of it (such a step moves
#: ΔBIC by about Σn_eff·1e-5 ≈ 0.01, a thousandth of the significance threshold; docs/benchmarks.md).
REFIT_COST_TOLERANCE = 1e-5
#: Times a refit that stops at its evaluation limit runs on from where it stopped (an effect with two
#: nearly exchangeable parameters walks its valley slowly; docs/validation.md). Still short after
#: these, it is said and not ranked with the converged ones.
REFIT_CONTINUATIONS = 3
#: Shares of an effect parameter's prior width probed before the refit (0 is its lower bound).
PROBE_SHARES = (0.05, 0.15, 0.35, 0.65, 1.0)


@dataclass(frozen=True, kw_only=True)
class CandidateJob:
    """What a worker needs to evaluate one candidate (picklable).

    ``fit_windows``, ``run_window``, ``evaluation``:
    :func:`~service.diagnosis.candidates.split_windows`; ``base_theta``: the base refitted on the fit
    windows (parameter key → value) and ``base_mean_squares`` its mean squared weighted residual there
    per target; ``train_theta`` the base as calibrated on the training window, and
    ``train_unidentified`` the keys that training did not identify; ``sample_fractions``: n_eff/n of
    each target's base residuals; ``target_scales``: the residual weights;
    ``base_evaluation_prediction``: the better base prediction of the evaluation half;
    ``onset_windows``: (training windows, first half of the test window) for the fit of a fault
    appearing in the test window; ``compared``: the operating filter's steps (``ModelData.compared``).
    A drift candidate (:mod:`service.diagnosis.drift`) has no ``signature``: its model carries the
    drift, and a step's onset is picked among the data steps ``drift_onsets``.
    """

    signature: Signature | None
    node: str
    model: AssembledModel
    data: MeasuredData
    substeps: int
    fit_windows: list[slice]
    run_window: slice
    evaluation: slice
    base_theta: dict[str, float]
    base_mean_squares: dict[str, float]
    sample_fractions: dict[str, float]
    target_scales: dict[str, float]
    base_evaluation_prediction: dict[str, np.ndarray]
    seed: int
    refit_max_nfev: int
    train_theta: dict[str, float] = field(default_factory=dict)
    train_unidentified: frozenset[str] = frozenset()
    onset_windows: tuple[list[slice], slice] | None = None
    compared: np.ndarray | None = None
    drift_onsets: tuple[int, ...] = ()

    def identity(self) -> tuple[str, str, str]:
        """(effect id, IRI, label) of the candidate."""
        if self.signature is None:
            return drift_identity(self.model.drifts[0])
        return self.signature.id, self.signature.iri, self.signature.label


def probe_ensemble(problem, theta0: np.ndarray, effect_columns: list[int],
                   theta_train: np.ndarray | None = None) -> np.ndarray:
    """The members :func:`probe_start` simulates: a grid of the effect parameters (the null and
    ``PROBE_SHARES`` of each prior width; all combinations) laid on ``theta0`` (the base refitted on
    the fit windows) and on ``theta_train`` (the base as trained)."""
    axes = []
    for column in effect_columns:
        lo, hi = problem.lower[column], problem.upper[column]
        axes.append(np.unique(np.clip(np.r_[theta0[column], lo + np.array(PROBE_SHARES) * (hi - lo)], lo, hi)))
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T if axes else np.empty((1, 0))
    starts = [theta0] if theta_train is None else [theta0, theta_train]
    ensemble = np.concatenate([np.repeat(start[None, :], len(grid), axis=0) for start in starts])
    ensemble[:, effect_columns] = np.tile(grid, (len(starts), 1))
    return ensemble


def probe_start(problem, theta0: np.ndarray, effect_columns: list[int], theta_train: np.ndarray | None = None,
                *, active_only: bool = False) -> np.ndarray:
    """The refit's start: the best point of :func:`probe_ensemble` (one simulate call). ``active_only``
    leaves out the grid points where any effect parameter sits at its value in ``theta0`` (its
    null): the best start with the effect switched on."""
    ensemble = probe_ensemble(problem, theta0, effect_columns, theta_train)
    cost = np.sum(problem.weighted_residuals(problem.run(ensemble)) ** 2, axis=1)
    if active_only:
        cost[np.any(ensemble[:, effect_columns] == theta0[effect_columns], axis=1)] = np.inf
    return ensemble[int(np.argmin(cost))]


def refit_calibrator(seed: int, max_nfev: int, *, n_starts: int = 1, n_candidates: int = 8) -> PointCalibrator:
    """The least squares of the comparison's refits: continued up to ``REFIT_CONTINUATIONS`` times where
    it stops at ``max_nfev``, without the jump check (a refit is read for θ, its standard errors and residuals)."""
    return PointCalibrator(n_starts=n_starts, n_candidates=n_candidates, random_state=seed, max_nfev=max_nfev,
                           continuations=REFIT_CONTINUATIONS, check_jumps=False, cost_tolerance=REFIT_COST_TOLERANCE)


class Fit(NamedTuple):
    """One hypothesis's fit: θ (all estimated parameters) and standard errors, the mean squared
    weighted residual and the effective sample fraction n_eff/n of its residuals per target, and
    the number of parameters it frees beyond the base's; whether the least-squares fit converged
    (continued where it stopped at its evaluation limit); each fitted step's weighted squared
    error (:func:`~service.diagnosis.ranking.residual_step_errors`)."""

    theta: np.ndarray
    standard_errors: np.ndarray
    mean_squares: dict[str, float]
    sample_fractions: dict[str, float]
    freed: int
    converged: bool
    step_errors: np.ndarray


def fit_onset(md: ModelData, job: CandidateJob, theta_train: np.ndarray, effect_columns: list[int],
              host: list[int] = ()):
    """The effect fitted as a fault that appears in the test window: the base parameters held at
    their training estimate, the effect null in the training window and fitted on the test window's
    first half, together with the base parameters in ``host`` (columns; :func:`host_columns`).
    The :class:`Fit` over the training window and that half."""
    before, after = job.onset_windows
    null = theta_train.copy()
    null[effect_columns] = null_values(job.model.estimated_parameters, effect_columns)
    host = list(host)
    free = effect_columns + host
    whole = md.problem([*before, after], default=null, target_scales=job.target_scales)
    unfaulted = ({} if host else
                 {i: md.simulate_targets(w, null[None, :]) for i, w in enumerate(before)})

    def simulate(theta_free: np.ndarray) -> dict[str, np.ndarray]:
        full = np.repeat(null[None, :], len(theta_free), axis=0)
        full[:, free] = theta_free
        faulted = md.simulate_targets(after, full)
        healthy = full.copy()
        healthy[:, effect_columns] = null[effect_columns]
        runs = [{k: np.repeat(v, len(theta_free), axis=0) for k, v in unfaulted[i].items()} if i in unfaulted
                else md.simulate_targets(w, healthy) for i, w in enumerate(before)]
        return {node: np.concatenate([run[node] for run in runs] + [faulted[node]], axis=1) for node in faulted}

    def effect_problem(default: np.ndarray) -> CalibrationProblem:
        return CalibrationProblem(
            parameter_names=tuple(whole.parameter_names[c] for c in free),
            lower=whole.lower[free], upper=whole.upper[free], simulate=simulate,
            observed=whole.observed, target_scales=job.target_scales, units=whole.units, default=default,
            vectorised_simulate=whole.vectorised_simulate,
        )

    at_null = null[free]
    own = list(range(len(effect_columns)))
    calibrator = refit_calibrator(job.seed, job.refit_max_nfev, n_starts=2 if host else 1,
                                  n_candidates=32 if host else 8)
    probe = effect_problem(at_null)  # the probe's grid and the fit's screen in one simulate call
    probe = with_prefetched_rows(probe, probe_ensemble(probe, at_null, own),
                                 probe.from_unit(calibrator.screen_points(probe)))
    problem = replace(probe, default=probe_start(probe, at_null, own))
    # with its host as trained the effect could only overshoot: the best start with it switched on
    # competes too, and the host's parameters get a wider screen
    active = probe_start(probe, at_null, own, active_only=True)[None, :] if host else None
    calibrator.fit(problem, candidates=active)
    theta = null.copy()
    theta[free] = calibrator.theta_
    standard_errors = np.zeros_like(theta)
    standard_errors[free] = calibrator.standard_errors_
    return fit_of(calibrator, theta, standard_errors, job.target_scales, len(free))


def fit_of(calibrator: PointCalibrator, theta: np.ndarray, standard_errors: np.ndarray,
           scales: dict[str, float], freed: int) -> Fit:
    """The :class:`Fit` of a fitted ``calibrator`` at θ (all estimated parameters)."""
    residuals = calibrator.residuals_
    return Fit(theta, standard_errors, mean_squares(residuals, scales), sample_fractions(residuals), freed,
               calibrator.converged_, residual_step_errors(residuals, scales))


def mean_squares(residuals: dict[str, np.ndarray], scales: dict[str, float]) -> dict[str, float]:
    """Mean squared weighted residual ((y − ŷ)/s)² per target (NaN where not measured)."""
    return {key: float(np.nanmean((values / scales[key]) ** 2)) for key, values in residuals.items()}


def sample_fractions(residuals: dict[str, np.ndarray]) -> dict[str, float]:
    """n_eff/n per target from the lag-1 autocorrelation of its own residual series (concatenating
    a power meter's watts with temperatures would let the watts decide every target's)."""
    return {key: effective_sample_fraction(values[np.isfinite(values)]) for key, values in residuals.items()}


def null_values(refs, columns: list[int]) -> np.ndarray:
    """The values at which the effect parameters in ``columns`` vanish."""
    return np.array([refs[c].spec.null if refs[c].spec.null is not None else refs[c].spec.default for c in columns])


def host_columns(job: CandidateJob) -> list[int]:
    """Columns of the parameters of the component the effect is spliced into (its host) when the
    training data identified none of them (then fitted with the effect); a host with some
    identified parameter was exercised, and stays as trained: no columns."""
    refs = job.model.estimated_parameters
    effect_components = {r.component for r in refs if r.key not in job.base_theta}
    hosts = {c.target for c in job.model.connections if c.source in effect_components} | {
        c.source for c in job.model.connections if c.target in effect_components}
    hosts -= effect_components
    columns = [j for j, r in enumerate(refs) if r.component in hosts]
    return columns if columns and all(refs[j].key in job.train_unidentified for j in columns) else []
