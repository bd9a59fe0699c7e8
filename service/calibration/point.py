"""Point calibration: bounded weighted least squares from several starts, with an identifiability verdict.

Cost ``C(θ) = ½ Σ_targets Σ_t ((y_t − ŷ_t(θ)) / s_target)²`` over the measured points (``s`` the
problem's target scales), minimised by :func:`scipy.optimize.least_squares` (trust-region
reflective) in the unit cube. Uncertainty: the sandwich ``Cov(θ̂) = (JᵀJ)⁻¹ Jᵀ D J (JᵀJ)⁻¹`` at θ̂,
``D`` each residual's target variance ``σ̂²_k = Σ_k r² / (n_k (1 − p/n))`` times its residuals'
long-run variance factor (Newey–West: :func:`~service.calibration.metrics.long_run_variance_factor`).
A parameter is poorly identified when it lies in a flat direction, is confounded with another, has a large relative
error, a 95 % interval across a bound, or a cost that jumps at ±2 SE. Method, rationale and
coverage: ``docs/calibration.md``, *Point calibration and identifiability*.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc
from sklearn.base import BaseEstimator
from sklearn.utils import check_random_state
from threadpoolctl import threadpool_limits

from service.calibration.lockstep import run_in_lockstep
from service.calibration.metrics import long_run_variance_factor
from service.calibration.problem import CalibrationProblem
from service.errors import CalibrationError

__all__ = ["PointCalibrator", "ParameterIdentifiability", "NonFiniteSimulationError"]


@dataclass(frozen=True)
class ParameterIdentifiability:
    """The verdict on one parameter: ``identified`` when ``reasons`` is empty."""

    name: str
    identified: bool
    reasons: tuple[str, ...]

    def to_dict(self) -> dict:
        return {"name": self.name, "identified": self.identified, "reasons": list(self.reasons)}


class NonFiniteSimulationError(CalibrationError):
    """Every start candidate's simulation gave NaN or infinite values where targets are compared."""


class PointCalibrator(BaseEstimator):
    """Multi-start bounded least squares on a :class:`CalibrationProblem` (scikit-learn style).

    :param n_starts: local optimisations, started from the best of the screened candidates.
    :param n_candidates: Latin-hypercube points screened in one simulate call to pick the starts.
    :param random_state: seed (int), ``numpy.random.RandomState`` or None.
    :param max_nfev: residual evaluations per start (each Jacobian is one more simulate call).
    :param diff_step: forward-difference step in the unit-scaled parameters.
    :param jacobian_with_residuals: simulate each trial point's Jacobian members in the same call as
        the point (one call per accepted step: right for a vectorised simulator, not for an FMU per
        member); None follows the problem's ``vectorised_simulate``.
    :param continuations: times a best start that stopped at ``max_nfev`` runs on from where it stopped.
    :param cost_tolerance: the least squares stop when a step lowers the cost by less than this share
        of it (SciPy's ``ftol``).
    :param check_jumps: run the jump check (one more simulate call); off where only θ, its standard
        errors and the residuals are read.
    :param flat_ratio: singular value ratio below which a direction counts as flat.
    :param flat_loading: |component| of a flat direction's vector that implicates a parameter.
    :param correlation_threshold: |ρ| above which two parameters are reported as confounded.
    :param relative_error_threshold: SE / |θ̂| above which a parameter is poorly identified.
    :param jump_threshold: |C(θ̂ ± 2·SE) − its linearised value| / the predicted rise above which the
        standard error is not trusted (``docs/calibration.md``).

    Results after :meth:`fit`: ``theta_`` (ndarray[n_parameters], physical units), ``covariance_``,
    ``standard_errors_``, ``correlation_``, ``singular_values_`` (of the unit-scaled Jacobian, largest
    first), ``identifiability_`` (``{name: ParameterIdentifiability}``), ``cost_``, ``residuals_``
    (``{target: ndarray[n_steps]}``, y − ŷ in the target's unit, NaN where not measured),
    ``prediction_`` (``{target: ndarray[n_steps]}``), ``start_costs_``, ``n_simulate_calls_``,
    ``n_simulated_members_``, ``converged_`` (the best start stopped at a tolerance, not at
    ``max_nfev``: after ``continuations`` further runs of ``max_nfev`` from where it stopped).
    """

    def __init__(
        self,
        n_starts: int = 4,
        n_candidates: int = 64,
        random_state: int | np.random.RandomState | None = None,
        max_nfev: int = 60,
        diff_step: float = 1e-4,
        flat_ratio: float = 1e-3,
        flat_loading: float = 0.2,
        correlation_threshold: float = 0.95,
        relative_error_threshold: float = 0.5,
        jump_threshold: float = 3.0,
        jacobian_with_residuals: bool | None = None,
        continuations: int = 0,
        check_jumps: bool = True,
        cost_tolerance: float = 1e-8,
    ) -> None:
        self.n_starts = n_starts
        self.n_candidates = n_candidates
        self.random_state = random_state
        self.max_nfev = max_nfev
        self.diff_step = diff_step
        self.flat_ratio = flat_ratio
        self.flat_loading = flat_loading
        self.correlation_threshold = correlation_threshold
        self.relative_error_threshold = relative_error_threshold
        self.jump_threshold = jump_threshold
        self.jacobian_with_residuals = jacobian_with_residuals
        self.continuations = continuations
        self.check_jumps = check_jumps
        self.cost_tolerance = cost_tolerance

    def fit(self, problem: CalibrationProblem, candidates: np.ndarray | None = None,
            kept: np.ndarray | None = None) -> PointCalibrator:
        """Estimate θ and its uncertainty; returns ``self``.

        :param candidates: ndarray[n, n_parameters], physical units: further start candidates
            screened with the Latin hypercube and the problem's default (e.g. a probe's best points).
        :param kept: ndarray[n, n_parameters], physical units: starts run besides the ``n_starts``
            screened ones, whatever their cost (a stored calibration: it cannot take the place of a
            start the screen would have kept, so the fit ends no worse than without it).
        """
        if self.n_starts < 1 or self.n_candidates < self.n_starts:
            raise CalibrationError(
                f"need 1 ≤ n_starts ≤ n_candidates, got n_starts={self.n_starts}, "
                f"n_candidates={self.n_candidates}"
            )
        self.n_simulate_calls_ = 0
        self.n_simulated_members_ = 0
        self._evaluations: dict[bytes, tuple] = {}
        self._evaluations_lock = threading.Lock()

        def simulate(theta: np.ndarray) -> dict[str, np.ndarray]:
            return self._run(problem, theta)

        with threadpool_limits(limits=1):
            starts = self._screen_starts(problem, candidates)
            if kept is not None:
                starts = np.vstack([starts, problem.to_unit(np.atleast_2d(kept))])
            if len(starts) > 1 and problem.vectorised_simulate:  # the starts' calls share simulate calls
                fits = run_in_lockstep(simulate, starts, lambda start, run: self._local_fit(problem, start, run))
            else:
                fits = [self._local_fit(problem, start, simulate) for start in starts]
            self.start_costs_ = np.array([fit.cost for fit in fits])
            best = fits[int(np.argmin(self.start_costs_))]
            for _ in range(self.continuations):  # least_squares' status 0: stopped at max_nfev
                if best.status > 0:
                    break
                best = self._local_fit(problem, best.x, simulate)
            self.converged_ = bool(best.status > 0)
            self.theta_ = problem.from_unit(best.x)
            self.cost_ = float(best.cost)
            outputs, _, jacobian = self._evaluate(problem, best.x, simulate, with_jacobian=True)
        del self._evaluations, self._evaluations_lock
        masks = problem.masks
        self.prediction_ = {key: outputs[key] for key in problem.target_keys}
        self.residuals_ = {
            key: np.where(masks[key], problem.observed[key] - outputs[key], np.nan)
            for key in problem.target_keys
        }
        self._set_uncertainty(problem, jacobian, best.fun)
        if self.check_jumps:
            self._check_linearisation(problem, best.x, best.fun, jacobian)
        return self

    def _run(self, problem: CalibrationProblem, theta: np.ndarray) -> dict[str, np.ndarray]:
        self.n_simulate_calls_ += 1
        self.n_simulated_members_ += theta.shape[0]
        return problem.run(theta)

    def screen_points(self, problem: CalibrationProblem) -> np.ndarray:
        """The seeded Latin hypercube :meth:`fit` screens for its starts, ``ndarray[n_candidates,
        n_parameters]`` in [0, 1] (the same points at every call for an int ``random_state``)."""
        rng = check_random_state(self.random_state)
        return qmc.LatinHypercube(d=problem.n_parameters, seed=rng.randint(2**31 - 1)).random(self.n_candidates)

    def _screen_starts(self, problem: CalibrationProblem, extra: np.ndarray | None = None) -> np.ndarray:
        """The ``n_starts`` lowest-cost points of a seeded Latin hypercube (+ the default and
        ``extra``), in [0, 1]."""
        candidates = self.screen_points(problem)
        if extra is not None:
            candidates = np.vstack([problem.to_unit(np.atleast_2d(extra)), candidates])
        if problem.default is not None:
            candidates = np.vstack([problem.to_unit(problem.default)[None, :], candidates])
        outputs = self._run(problem, problem.from_unit(candidates))
        costs = 0.5 * np.sum(problem.weighted_residuals(outputs)**2, axis=1)
        finite = np.flatnonzero(np.isfinite(costs))
        if not finite.size:
            first = {key: int(np.argmax(~np.isfinite(outputs[key][0]) & masks))
                     for key, masks in problem.masks.items() if not np.isfinite(outputs[key][0][masks]).all()}
            raise NonFiniteSimulationError(
                "the simulation gave NaN or infinite values for every start candidate, at "
                + ", ".join(f"target {key} (first at step {step})" for key, step in first.items()))
        return candidates[finite[np.argsort(costs[finite], kind="stable")[: self.n_starts]]]

    def _local_fit(self, problem: CalibrationProblem, start: np.ndarray, simulate: Callable):
        fused = problem.vectorised_simulate if self.jacobian_with_residuals is None else self.jacobian_with_residuals

        def residuals(unit_theta: np.ndarray) -> np.ndarray:
            return self._evaluate(problem, unit_theta, simulate, with_jacobian=fused)[1]

        def jacobian(unit_theta: np.ndarray) -> np.ndarray:
            return self._evaluate(problem, unit_theta, simulate, with_jacobian=True)[2]

        return least_squares(
            residuals, start, jac=jacobian, bounds=(0.0, 1.0), method="trf", max_nfev=self.max_nfev,
            ftol=self.cost_tolerance,
        )

    def _evaluate(self, problem: CalibrationProblem, unit_theta: np.ndarray, simulate: Callable, *,
                  with_jacobian: bool):
        """(outputs {target: ndarray[n_steps]}, weighted residuals, Jacobian or None) at
        ``unit_theta`` in one ``simulate`` call (physical θ rows → outputs), remembered for the rest
        of the fit. The Jacobian is by forward differences in the unit cube (backward at the upper
        bound)."""
        key = np.asarray(unit_theta, dtype=float).tobytes()
        with self._evaluations_lock:
            known = self._evaluations.get(key)
        if known is not None and (known[2] is not None or not with_jacobian):
            return known
        members = unit_theta[None, :]
        if with_jacobian:
            n_par = problem.n_parameters
            step = np.where(unit_theta + self.diff_step <= 1.0, self.diff_step, -self.diff_step)
            members = np.repeat(members, n_par + 1, axis=0)
            members[1:][np.diag_indices(n_par)] += step
        outputs = simulate(problem.from_unit(members))
        residuals = problem.weighted_residuals(outputs)
        jacobian = ((residuals[1:] - residuals[0]) / step[:, None]).T if with_jacobian else None
        known = ({target: values[0] for target, values in outputs.items()}, residuals[0], jacobian)
        with self._evaluations_lock:
            if len(self._evaluations) >= 64:  # the starts' last points are what fit() asks for again
                self._evaluations.pop(next(iter(self._evaluations)))
            self._evaluations[key] = known
        return known

    def _set_uncertainty(self, problem: CalibrationProblem, jacobian: np.ndarray, residuals: np.ndarray) -> None:
        n, p = residuals.size, problem.n_parameters
        if n <= p:
            raise CalibrationError(f"{n} measured values cannot determine {p} parameters (need n > p)")
        counts = np.array([mask.sum() for mask in problem.masks.values()])
        target_of = np.repeat(np.arange(counts.size), counts)
        noise_variance = np.divide(np.bincount(target_of, weights=residuals**2, minlength=counts.size), counts * (1 - p / n),
                                   out=np.zeros(counts.size), where=counts > 0)
        # autocorrelated residuals (a misfit that lasts hours) carry fewer independent values: each
        # target's variance is its long-run variance (Newey–West over its measured steps)
        for k, mask in enumerate(problem.masks.values()):
            series = np.full(mask.shape, np.nan)
            series[mask] = residuals[target_of == k]
            noise_variance[k] *= long_run_variance_factor(series)
        u, singular, vt = np.linalg.svd(jacobian, full_matrices=False)
        self.singular_values_ = singular
        floor = singular[0] * 1e-12 if singular[0] > 0 else 1e-300
        clipped = np.maximum(singular, floor)
        width = problem.upper - problem.lower
        meat = u.T @ (u * noise_variance[target_of][:, None])
        with np.errstate(over="ignore", invalid="ignore"):  # a direction the data do not see: an infinite variance
            unit_covariance = (vt.T / clipped) @ meat @ (vt / clipped[:, None])
        self.covariance_ = unit_covariance * np.outer(width, width)
        self.standard_errors_ = np.sqrt(np.diag(self.covariance_))
        self.correlation_ = _correlation(self.covariance_, self.standard_errors_)
        self.identifiability_ = self._verdicts(problem, singular, vt)

    def _verdicts(self, problem: CalibrationProblem, singular: np.ndarray, vt: np.ndarray) -> dict:
        names = problem.parameter_names
        reasons: dict[str, list[str]] = {name: [] for name in names}
        ratios = singular / singular[0] if singular[0] > 0 else np.zeros_like(singular)
        for ratio, direction in zip(ratios, vt):
            if ratio >= self.flat_ratio:
                continue
            involved = [names[i] for i in np.flatnonzero(np.abs(direction) > self.flat_loading)]
            for name in involved:
                partners = [other for other in involved if other != name]
                shared = f"; moves with {', '.join(partners)}" if partners else ""
                reasons[name].append(f"flat direction (singular value {ratio:.1e} × the largest{shared})")
        for i, name in enumerate(names):
            rho = self.correlation_[i].copy()
            rho[i] = 0.0
            j = int(np.argmax(np.abs(rho)))
            if abs(rho[j]) > self.correlation_threshold:
                reasons[name].append(f"correlated with {names[j]} (ρ = {rho[j]:+.3f})")
            se, value = self.standard_errors_[i], self.theta_[i]
            lo, hi = problem.lower[i], problem.upper[i]
            reference = max(abs(value), 0.01 * (hi - lo))
            if se > self.relative_error_threshold * reference:
                reasons[name].append(f"relative standard error {100 * se / reference:.0f} %")
            if value - 1.96 * se < lo or value + 1.96 * se > hi:
                reasons[name].append(
                    f"95 % interval [{value - 1.96 * se:.4g}, {value + 1.96 * se:.4g}] crosses the "
                    f"prior bounds [{lo:.4g}, {hi:.4g}]"
                )
        return {name: ParameterIdentifiability(name, not why, tuple(why)) for name, why in reasons.items()}

    def _check_linearisation(self, problem: CalibrationProblem, unit_theta: np.ndarray, residuals: np.ndarray,
                             jacobian: np.ndarray) -> None:
        """Add the jump reason (``docs/calibration.md``) to the parameters still called identified;
        ``jacobian`` is that of the weighted residuals in the unit cube at ``unit_theta``."""
        names = problem.parameter_names
        checked = [j for j, name in enumerate(names) if self.identifiability_[name].identified]
        if not checked:
            return
        step = 2.0 * self.standard_errors_ / (problem.upper - problem.lower)
        members = np.repeat(unit_theta[None, :], 2 * len(checked), axis=0)
        for k, j in enumerate(checked):
            members[2 * k, j] = min(unit_theta[j] + step[j], 1.0)
            members[2 * k + 1, j] = max(unit_theta[j] - step[j], 0.0)
        moved = problem.weighted_residuals(self._run(problem, problem.from_unit(members)))
        cost = 0.5 * residuals @ residuals
        for k, j in enumerate(checked):
            worst = 0.0
            for row in (2 * k, 2 * k + 1):
                linear = jacobian[:, j] * (members[row, j] - unit_theta[j])
                rise = 0.5 * linear @ linear
                if rise > 0:
                    predicted = cost + residuals @ linear + rise
                    ratio = abs(0.5 * moved[row] @ moved[row] - predicted) / rise
                    worst = max(worst, ratio if np.isfinite(ratio) else np.inf)
            if worst > self.jump_threshold:
                name = names[j]
                self.identifiability_[name] = ParameterIdentifiability(name, False, (
                    f"the cost jumps at the estimate: at ±2 standard errors it is off the linearisation's "
                    f"prediction by {worst:.1f}× the rise predicted, so the standard error means nothing",))


def _correlation(covariance: np.ndarray, standard_errors: np.ndarray) -> np.ndarray:
    """Correlation matrix of ``covariance``; a parameter with a zero standard error (residuals that
    are exactly zero) correlates with nothing: 0 off the diagonal, 1 on it."""
    scale = np.outer(standard_errors, standard_errors)
    with np.errstate(invalid="ignore"):  # an unobserved direction's infinite variance: no correlation to tell (NaN)
        correlation = np.divide(covariance, scale, out=np.zeros_like(covariance), where=scale > 0)
    np.fill_diagonal(correlation, 1.0)
    return correlation
