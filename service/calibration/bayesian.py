"""Bayesian calibration (Kennedy–O'Hagan) by parallel-tempering MCMC, and the posterior predictive.

θ and every target's discrepancy hyperparameters are sampled together from the posterior of
:class:`~service.calibration.koh_likelihood.KennedyOHaganLikelihood` by
:class:`~service.calibration.parallel_tempering.ParallelTemperingSampler`, started around a
:class:`~service.calibration.point.PointCalibrator` estimate. Prediction (Eqs. 16–22): per posterior
draw (θ, φ), the model output + the discrepancy GP conditioned on that draw's training residuals +
white noise N(0, σ_n²); quantiles over the draws give the median and intervals. Source: Bjørnskov,
Jradi & Wetter, Sec. 4. GP inputs, moves, threads: ``docs/calibration.md``, *Bayesian calibration*.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import emcee
import numpy as np
from sklearn.base import BaseEstimator, clone
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from service.calibration.koh_likelihood import HyperparameterBounds, KennedyOHaganLikelihood
from service.calibration.matern_gp import InputDistances, conditional
from service.calibration.metrics import TargetMetrics, target_metrics
from service.calibration.parallel_tempering import ParallelTemperingSampler, geometric_betas
from service.calibration.point import ParameterIdentifiability, PointCalibrator
from service.calibration.problem import CalibrationProblem
from service.errors import CalibrationError

__all__ = ["BayesianCalibrator", "PosteriorPredictive", "default_moves", "posterior_identifiability", "POSTERIOR_NARROWING"]

_DRAW_CHUNK = 8

#: A parameter whose posterior 16–84 % interval is narrower than this share of its uniform prior's
#: (0.68 of the range) is identified: the data at least halved the range it may lie in.
POSTERIOR_NARROWING = 0.5


def posterior_identifiability(problem: CalibrationProblem, q16: np.ndarray, q84: np.ndarray, converged: bool = True,
                              ) -> dict[str, ParameterIdentifiability]:
    """Per parameter: identified by the data where its posterior 16–84 % interval spans less than
    :data:`POSTERIOR_NARROWING` of its prior's (the point fit's verdict, which starts the sampler, is a
    linearisation at one point: a bounded posterior can be narrow where that fit's interval is wide).
    A sampler that did not converge gives no verdict: none is called identified."""
    verdicts = {}
    for j, name in enumerate(problem.parameter_names):
        share = float((q84[j] - q16[j]) / (0.68 * (problem.upper[j] - problem.lower[j])))
        why = (("the sampler did not converge: its draws are no posterior to judge by",) if not converged else
               () if share < POSTERIOR_NARROWING else (
                   f"its posterior 16–84 % interval spans {100 * share:.0f} % of its prior's: the data narrow it less "
                   f"than {1 / POSTERIOR_NARROWING:g}-fold",))
        verdicts[name] = ParameterIdentifiability(name, not why, why)
    return verdicts


@dataclass(frozen=True)
class PosteriorPredictive:
    """Posterior predictive draws per target on one window.

    ``draws``: model + discrepancy + noise, ``ndarray[n_draws, n_steps]``; ``model_draws``: the model
    output alone (θ uncertainty only); ``discrepancy_mean``: the mean over draws of the conditioned
    discrepancy (what the model misses, in the target's unit); ``n_parameters``: estimated θ count
    (the p of ASHRAE Guideline 14).
    """

    draws: dict[str, np.ndarray]
    model_draws: dict[str, np.ndarray]
    discrepancy_mean: dict[str, np.ndarray]
    units: dict[str, str]
    n_parameters: int

    @property
    def median(self) -> dict[str, np.ndarray]:
        return {key: np.median(values, axis=0) for key, values in self.draws.items()}

    def interval(self, target: str, level: float) -> tuple[np.ndarray, np.ndarray]:
        """Central ``level`` interval (e.g. 0.9) of the predictive at every step: ``(lower, upper)``."""
        if not 0.0 < level < 1.0:
            raise CalibrationError(f"interval level {level} must lie in (0, 1)")
        if target not in self.draws:
            raise KeyError(f"no prediction for target {target!r}; have {', '.join(self.draws)}")
        lower, upper = np.quantile(self.draws[target], [(1 - level) / 2, (1 + level) / 2], axis=0)
        return lower, upper

    def metrics(
        self, observed: Mapping[str, np.ndarray], levels: Sequence[float] = (0.5, 0.68, 0.8, 0.9, 0.95, 0.99)
    ) -> dict[str, TargetMetrics]:
        """:func:`service.calibration.metrics.target_metrics` of the median and the intervals, per target."""
        median = self.median
        return {
            key: target_metrics(
                observed[key], median[key], n_parameters=self.n_parameters,
                intervals={level: self.interval(key, level) for level in levels},
                unit=self.units.get(key, ""), target=key,
            )
            for key in self.draws
        }


def default_moves() -> list[tuple[emcee.moves.RedBlueMove, float]]:
    """Differential evolution (Ter Braak 2006; Nelson et al. 2013) 80 % of the steps, the stretch
    move 20 %: the KOH posterior is long and narrow along the directions the data confound, where
    the stretch move alone mixes slowly (``docs/calibration.md``, *Proposal moves*)."""
    return [(emcee.moves.DEMove(), 0.8), (emcee.moves.StretchMove(), 0.2)]


class BayesianCalibrator(BaseEstimator):
    """Kennedy–O'Hagan calibration by parallel-tempering ensemble MCMC (scikit-learn style).

    :param n_walkers: walkers per temperature (default: the even number ≥ max(16, 2·n_dim + 2)).
    :param n_temperatures: rungs of the temperature ladder (1 disables tempering).
    :param max_temperature: hottest temperature (default: the geometric spacing of
        :func:`~service.calibration.parallel_tempering.geometric_betas`).
    :param max_steps: step cap; a run that reaches it reports ``converged_ = False``.
    :param check_interval: steps between IAT checks.
    :param iat_multiple: the chain must be this many IATs long (20).
    :param iat_rtol: and the IAT estimate must have changed less than this since the last check.
    :param random_state: seed, RandomState or None; a seeded fit is reproducible.
    :param gp_inputs: ``"auto"`` (the problem's ``gp_inputs``, else the time index), ``"time"`` (the time
        index) or indices of the problem's ``gp_inputs`` columns.
    :param hyperparameter_bounds: priors of the GP hyperparameters (default :class:`HyperparameterBounds`).
    :param max_points_per_target: measured points per target in the GP.
    :param adapt_ladder: adapt the temperatures (Vousden et al. 2016).
    :param moves: the ensemble proposal (:class:`~service.calibration.parallel_tempering.ParallelTemperingSampler`);
        None: :func:`default_moves`.
    :param point_calibrator: an unfitted :class:`PointCalibrator` for the start (default 2 starts).
    :param progress: show a rich progress bar.
    :param on_check: hears after each convergence check how far sampling is (a job's progress).

    Results: ``samples_`` (ndarray[n_samples, n_parameters], burn-in discarded, thinned),
    ``chain_`` (the whole β = 1 chain, ndarray[n_steps, n_walkers, n_parameters + n_hyper], for traces),
    ``hyper_samples_``, ``hyper_names_``, ``discrepancy_`` (per target the quantiles of the GP's σ_f,
    σ_n and length scales, :meth:`KennedyOHaganLikelihood.hyperparameter_quantiles`), ``median_``,
    ``quantile16_``, ``quantile84_``, ``map_`` and
    ``map_hyper_`` (the highest-posterior β = 1 sample seen), ``log_probability_`` (of the samples),
    ``converged_``, ``iat_``, ``n_steps_``, ``convergence_``, ``acceptance_`` (β = 1 chain),
    ``identifiability_`` (per parameter, from the posterior: :func:`posterior_identifiability`),
    ``swap_rate_`` (per neighbouring temperature pair), ``betas_``, ``point_calibrator_``,
    ``likelihood_``, ``problem_``.
    """

    def __init__(
        self,
        n_walkers: int | None = None,
        n_temperatures: int = 4,
        max_temperature: float | None = None,
        max_steps: int = 20000,
        check_interval: int = 100,
        iat_multiple: float = 20.0,
        iat_rtol: float = 0.05,
        random_state: int | np.random.RandomState | None = None,
        gp_inputs: str | Sequence[int] = "auto",
        hyperparameter_bounds: HyperparameterBounds | None = None,
        max_points_per_target: int = 144,
        adapt_ladder: bool = True,
        moves=None,
        point_calibrator: PointCalibrator | None = None,
        progress: bool = True,
        on_check: Callable[[str], None] | None = None,
    ) -> None:
        self.n_walkers = n_walkers
        self.n_temperatures = n_temperatures
        self.max_temperature = max_temperature
        self.max_steps = max_steps
        self.check_interval = check_interval
        self.iat_multiple = iat_multiple
        self.iat_rtol = iat_rtol
        self.random_state = random_state
        self.gp_inputs = gp_inputs
        self.hyperparameter_bounds = hyperparameter_bounds
        self.max_points_per_target = max_points_per_target
        self.adapt_ladder = adapt_ladder
        self.moves = moves
        self.point_calibrator = point_calibrator
        self.progress = progress
        self.on_check = on_check

    def _raw_gp_inputs(self, problem: CalibrationProblem, time_offset: int) -> tuple[np.ndarray | None, tuple | None]:
        """The raw GP input array for a window (None: the time index) and the input names."""
        choice = self.gp_inputs
        if isinstance(choice, str):
            if choice not in ("auto", "time"):
                raise CalibrationError(f"gp_inputs={choice!r}: expected 'auto', 'time' or column indices")
            if choice == "time" or problem.gp_inputs is None:
                return np.arange(time_offset, time_offset + problem.n_steps, dtype=float)[:, None], ("time",)
            return problem.gp_inputs, problem.gp_input_names
        if problem.gp_inputs is None:
            raise CalibrationError(f"gp_inputs={list(choice)} selects columns, but the problem has no gp_inputs")
        columns = [int(c) for c in choice]
        n_features = problem.gp_inputs.shape[1]
        if not columns or min(columns) < -n_features or max(columns) >= n_features:
            raise CalibrationError(f"gp_inputs columns {columns} out of range for {n_features} problem gp_inputs")
        names = problem.gp_input_names or tuple(f"gp_input{c}" for c in range(n_features))
        return problem.gp_inputs[:, columns], tuple(names[c] for c in columns)

    def fit(self, problem: CalibrationProblem) -> BayesianCalibrator:
        """Sample the posterior of θ and the discrepancy hyperparameters; returns ``self``."""
        rng = check_random_state(self.random_state)
        with threadpool_limits(limits=1):
            start = clone(self.point_calibrator) if self.point_calibrator is not None else PointCalibrator(n_starts=2)
            start.set_params(random_state=rng.randint(2**31 - 1)).fit(problem)
            raw_inputs, names = self._raw_gp_inputs(problem, 0)
            likelihood = KennedyOHaganLikelihood(
                problem, raw_inputs, names, self.hyperparameter_bounds or HyperparameterBounds(),
                self.max_points_per_target,
            )
            n_walkers = self.n_walkers or max(16, 2 * likelihood.n_dim + 2)
            n_walkers += n_walkers % 2
            sampler = ParallelTemperingSampler(
                likelihood.evaluate, n_walkers, likelihood.n_dim,
                betas=geometric_betas(self.n_temperatures, likelihood.n_dim, self.max_temperature),
                adapt_ladder=self.adapt_ladder, moves=self.moves if self.moves is not None else default_moves(),
                random_state=rng.randint(2**31 - 1),
            )
            residual_std = {key: float(np.nanstd(start.residuals_[key])) for key in problem.target_keys}
            initial = likelihood.initial_ensemble(start.theta_, residual_std, n_walkers, rng, start.covariance_)
            convergence = sampler.run(
                initial, self.max_steps, self.check_interval, self.iat_multiple, self.iat_rtol, self.progress,
                self.on_check,
            )
        p = problem.n_parameters
        backend = sampler.backend
        chain = backend.get_chain(discard=convergence.burn_in, thin=convergence.thin, flat=True)
        self.samples_ = chain[:, :p]
        self.hyper_samples_ = chain[:, p:]
        self.log_probability_ = backend.get_log_prob(discard=convergence.burn_in, thin=convergence.thin, flat=True)
        self.median_, self.quantile16_, self.quantile84_ = np.quantile(self.samples_, [0.5, 0.16, 0.84], axis=0)
        self.chain_ = backend.get_chain()
        every = self.chain_.reshape(-1, self.chain_.shape[-1])
        best = every[int(np.argmax(backend.get_log_prob(flat=True)))]
        self.map_, self.map_hyper_ = best[:p], best[p:]
        self.parameter_names_ = problem.parameter_names
        self.hyper_names_ = likelihood.hyper_names
        self.converged_ = convergence.converged
        self.iat_ = convergence.iat
        self.n_steps_ = convergence.n_steps
        self.convergence_ = convergence
        self.acceptance_ = float(sampler.acceptance_fraction[0])
        self.swap_rate_ = sampler.swap_acceptance_fraction
        self.betas_ = sampler.betas
        self.point_calibrator_ = start
        self.likelihood_ = likelihood
        self.problem_ = problem
        self.discrepancy_ = likelihood.hyperparameter_quantiles(np.hstack([self.samples_, self.hyper_samples_]))
        self.identifiability_ = posterior_identifiability(problem, self.quantile16_, self.quantile84_,
                                                          convergence.converged)
        return self

    def predict(self, problem: CalibrationProblem, n_draws: int = 200,
                steps_from_training_start: int | None = None) -> PosteriorPredictive:
        """Posterior predictive on a window (the training window or a test window).

        :param problem: the window to predict, with the same parameters and targets as the training
            problem (its observations are not used here; see :meth:`PosteriorPredictive.metrics`).
        :param n_draws: posterior draws (with replacement when there are fewer samples).
        :param steps_from_training_start: where the window's first step lies, in steps after the
            training window's first step (0: the training window itself, or a window starting with
            it); None: right after the training window. Only a discrepancy over the time index
            (``gp_inputs="time"``, or ``"auto"`` on a problem without inputs) depends on it.
        """
        check_is_fitted(self, "samples_")
        if problem.parameter_names != self.parameter_names_:
            raise ValueError("the prediction window's parameters differ from the calibrated parameters")
        missing = sorted(set(self.problem_.target_keys) - set(problem.target_keys))
        if missing:
            raise ValueError(f"the prediction window lacks targets {', '.join(missing)}")
        likelihood = self.likelihood_
        rng = check_random_state(self.random_state)
        pick = rng.choice(self.samples_.shape[0], size=n_draws, replace=self.samples_.shape[0] < n_draws)
        vectors = np.hstack([self.samples_[pick], self.hyper_samples_[pick]])
        with threadpool_limits(limits=1):
            train_outputs = self.problem_.run(vectors[:, : likelihood.n_theta])
            test_outputs = problem.run(vectors[:, : likelihood.n_theta])
            hyper = likelihood.hyperparameters(vectors)
            offset = self.problem_.n_steps if steps_from_training_start is None else int(steps_from_training_start)
            raw, _ = self._raw_gp_inputs(problem, offset)
            test_inputs = likelihood.scale_inputs(raw)
            draws, discrepancy_mean = {}, {}
            for key in self.problem_.target_keys:
                index = likelihood.train_index[key]
                residuals = self.problem_.observed[key][index] - train_outputs[key][:, index]
                train_inputs = likelihood.train_inputs[key]
                distances = (
                    InputDistances(train_inputs), InputDistances(train_inputs, test_inputs), InputDistances(test_inputs)
                )
                h = hyper[key]
                delta, mean_sum = np.empty((n_draws, problem.n_steps)), np.zeros(problem.n_steps)
                for start in range(0, n_draws, _DRAW_CHUNK):
                    part = slice(start, min(start + _DRAW_CHUNK, n_draws))
                    mean, covariance = conditional(
                        residuals[part], *distances, h.amplitude[part], h.length_scales[part], h.noise_std[part]
                    )
                    delta[part] = mean + _correlated_normal(covariance, h.amplitude[part], rng)
                    mean_sum += mean.sum(axis=0)
                noise = h.noise_std[:, None] * rng.standard_normal((n_draws, problem.n_steps))
                draws[key] = test_outputs[key] + delta + noise
                discrepancy_mean[key] = mean_sum / n_draws
        return PosteriorPredictive(
            draws=draws,
            model_draws={key: test_outputs[key] for key in self.problem_.target_keys},
            discrepancy_mean=discrepancy_mean,
            units=dict(problem.units),
            n_parameters=self.problem_.n_parameters,
        )


def _correlated_normal(covariance: np.ndarray, amplitude: np.ndarray, rng: np.random.RandomState) -> np.ndarray:
    """One draw of N(0, Σ) per stacked covariance, ``ndarray[s, m]``.

    The conditional covariance is positive semi-definite up to round-off; a jitter of 1e-10 σ_f² on
    the diagonal (raised 100-fold until the Cholesky factorisation succeeds, at most 1e-4 σ_f²)
    makes it factorisable without visibly widening the intervals.
    """
    m = covariance.shape[-1]
    eye = np.eye(m)
    for jitter in (1e-10, 1e-8, 1e-6, 1e-4):
        try:
            factor = np.linalg.cholesky(covariance + (jitter * amplitude**2)[:, None, None] * eye)
            break
        except np.linalg.LinAlgError:
            continue
    else:
        raise ValueError("the discrepancy's conditional covariance is not positive semi-definite")
    return np.einsum("sij,sj->si", factor, rng.standard_normal((covariance.shape[0], m)))
