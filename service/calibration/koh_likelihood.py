"""Kennedy–O'Hagan likelihood: model output + GP discrepancy + white noise, per target.

For every target ``k`` (Kennedy & O'Hagan 2001; Bjørnskov, Jradi & Wetter, Sec. 4)::

    y_k(t) = η_k(t; θ) + δ_k(x_t) + ε_k(t),   δ_k ~ GP(0, σ_f,k² · matern32(x, x'; ℓ_k)),   ε_k ~ N(0, σ_n,k²)

Targets are independent given θ: the log-likelihood sums their GP log marginal likelihoods. Sampled
vector: ``θ (physical units) | per target: log(σ_f / s_k), log ℓ_k,1 … log ℓ_k,d, log(σ_n / s_k)``,
``s_k`` the target scale, GP inputs scaled to [0, 1] over the training window. Priors: θ uniform on
its bounds, the hyperparameters log-uniform on :class:`HyperparameterBounds` (``docs/calibration.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.calibration.matern_gp import InputDistances, log_marginal_likelihood
from service.calibration.problem import CalibrationProblem
from service.errors import CalibrationError

__all__ = ["HyperparameterBounds", "KennedyOHaganLikelihood", "TargetHyperparameters"]


@dataclass(frozen=True)
class HyperparameterBounds:
    """Bounds of the log-uniform hyperparameter priors; amplitude and noise relative to the target scale,
    length scales in units of the [0, 1]-scaled GP inputs."""

    amplitude: tuple[float, float] = (1e-3, 10.0)
    length_scale: tuple[float, float] = (0.02, 10.0)
    noise: tuple[float, float] = (1e-3, 2.0)

    def __post_init__(self) -> None:
        for label in ("amplitude", "length_scale", "noise"):
            lo, hi = getattr(self, label)
            if not 0.0 < lo < hi:
                raise CalibrationError(f"hyperparameter bounds {label}=({lo}, {hi}): need 0 < lower < upper")


@dataclass(frozen=True)
class TargetHyperparameters:
    """One target's GP hyperparameters for a batch, in the target's unit and the scaled-input unit."""

    amplitude: np.ndarray  # σ_f, ndarray[n]
    length_scales: np.ndarray  # ℓ, ndarray[n, d]
    noise_std: np.ndarray  # σ_n, ndarray[n]


class KennedyOHaganLikelihood:
    """Log prior and log-likelihood of ``[θ, hyperparameters]`` batches for a calibration problem.

    :param problem: the training window.
    :param gp_inputs: ``ndarray[n_steps, d]`` raw GP inputs of the training window (None: the time
        index 0 … n_steps − 1).
    :param input_names: one name per GP input column (default ``time`` or ``gp_input<j>``).
    :param bounds: hyperparameter prior bounds.
    :param max_points_per_target: measured points per target that enter the GP.
    """

    def __init__(
        self,
        problem: CalibrationProblem,
        gp_inputs: np.ndarray | None = None,
        input_names: tuple[str, ...] | None = None,
        bounds: HyperparameterBounds = HyperparameterBounds(),
        max_points_per_target: int = 144,
    ) -> None:
        if max_points_per_target < 2:
            raise CalibrationError(f"max_points_per_target={max_points_per_target}: need at least 2")
        self.problem = problem
        self.bounds = bounds
        raw = np.arange(problem.n_steps, dtype=float)[:, None] if gp_inputs is None else np.asarray(gp_inputs, float)
        raw = raw[:, None] if raw.ndim == 1 else raw
        if raw.shape[0] != problem.n_steps or raw.ndim != 2:
            raise ValueError(f"gp_inputs has shape {raw.shape}, expected ({problem.n_steps}, n_features)")
        self.input_offset = raw.min(axis=0)
        self.input_span = raw.max(axis=0) - self.input_offset
        constant = np.flatnonzero(self.input_span <= 0.0)
        if constant.size:
            raise CalibrationError(f"gp input column {constant[0]} is constant over the training window")
        self.n_inputs = raw.shape[1]
        if input_names is None:
            input_names = ("time",) if gp_inputs is None else tuple(f"gp_input{j}" for j in range(self.n_inputs))
        if len(input_names) != self.n_inputs:
            raise ValueError(f"{len(input_names)} input names for {self.n_inputs} gp input columns")
        self.input_names = tuple(input_names)
        inputs = self.scale_inputs(raw)
        masks = problem.masks
        self.train_index: dict[str, np.ndarray] = {}
        self.train_inputs: dict[str, np.ndarray] = {}
        for key in problem.target_keys:
            valid = np.flatnonzero(masks[key])
            if valid.size > max_points_per_target:
                valid = valid[np.unique(np.round(np.linspace(0, valid.size - 1, max_points_per_target)).astype(int))]
            self.train_index[key] = valid
            self.train_inputs[key] = inputs[valid]
        # targets measured at the same steps share their distances and are evaluated in one GP call
        groups: dict[bytes, list[str]] = {}
        for key in problem.target_keys:
            groups.setdefault(self.train_index[key].tobytes(), []).append(key)
        self._groups = [(InputDistances(self.train_inputs[keys[0]]), keys) for keys in groups.values()]
        self.n_theta = problem.n_parameters
        self.n_hyper_per_target = self.n_inputs + 2
        self.n_dim = self.n_theta + len(problem.target_keys) * self.n_hyper_per_target
        hyper_names, hyper_lower, hyper_upper = [], [], []
        for key in problem.target_keys:
            entries = [("log_amplitude", bounds.amplitude)]
            entries += [(f"log_length_scale:{name}", bounds.length_scale) for name in self.input_names]
            entries += [("log_noise", bounds.noise)]
            for label, (lo, hi) in entries:
                hyper_names.append(f"{key}:{label}")
                hyper_lower.append(np.log(lo))
                hyper_upper.append(np.log(hi))
        self.hyper_names = tuple(hyper_names)
        self.names = problem.parameter_names + self.hyper_names
        self.lower = np.concatenate([problem.lower, hyper_lower])
        self.upper = np.concatenate([problem.upper, hyper_upper])
        self._log_prior_density = -float(np.sum(np.log(self.upper - self.lower)))

    def scale_inputs(self, raw: np.ndarray) -> np.ndarray:
        """Raw GP inputs → the training window's [0, 1] scale (test windows may fall outside)."""
        raw = np.asarray(raw, dtype=float)
        raw = raw[:, None] if raw.ndim == 1 else raw
        if raw.ndim != 2 or raw.shape[1] != self.n_inputs:
            raise ValueError(f"gp inputs of shape {raw.shape}, expected (n_steps, {self.n_inputs})")
        return (raw - self.input_offset) / self.input_span

    def _check(self, batch: np.ndarray) -> np.ndarray:
        batch = np.asarray(batch, dtype=float)
        if batch.ndim != 2 or batch.shape[1] != self.n_dim:
            raise ValueError(f"batch has shape {batch.shape}, expected (n_walkers, {self.n_dim})")
        return batch

    def hyperparameters(self, batch: np.ndarray) -> dict[str, TargetHyperparameters]:
        """Per target σ_f, ℓ and σ_n of a batch (amplitude and noise in the target's unit)."""
        batch = self._check(batch)
        result = {}
        for k, key in enumerate(self.problem.target_keys):
            start = self.n_theta + k * self.n_hyper_per_target
            block = np.exp(batch[:, start : start + self.n_hyper_per_target])
            scale = self.problem.target_scales[key]
            result[key] = TargetHyperparameters(block[:, 0] * scale, block[:, 1:-1], block[:, -1] * scale)
        return result

    def hyperparameter_quantiles(self, batch: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
        """Per target the 16, 50 and 84 % quantiles over ``batch`` (posterior draws) of σ_f and σ_n (the
        target's unit) and of each length scale in its input's own unit (``length_scale:<input>``; the
        scaled ℓ times the input's span over the training window)."""
        levels = [0.16, 0.5, 0.84]
        result = {}
        for key, hyper in self.hyperparameters(batch).items():
            entry = {"amplitude": np.quantile(hyper.amplitude, levels), "noise": np.quantile(hyper.noise_std, levels)}
            for i, name in enumerate(self.input_names):
                entry[f"length_scale:{name}"] = np.quantile(hyper.length_scales[:, i] * self.input_span[i], levels)
            result[key] = entry
        return result

    def log_prior(self, batch: np.ndarray) -> np.ndarray:
        """Log density of the independent uniform / log-uniform priors; −inf outside the bounds."""
        batch = self._check(batch)
        inside = np.all((batch >= self.lower) & (batch <= self.upper), axis=1)
        return np.where(inside, self._log_prior_density, -np.inf)

    def evaluate(self, batch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(log_prior, log_likelihood)``, each ``ndarray[n]``, with one simulate call for the batch.

        Members outside the prior support and members whose simulation is not finite get a
        log-likelihood of −inf.
        """
        batch = self._check(batch)
        log_prior = self.log_prior(batch)
        log_likelihood = np.full(batch.shape[0], -np.inf)
        inside = np.isfinite(log_prior)
        if inside.any():
            members = batch[inside]
            outputs = self.problem.run(members[:, : self.n_theta])
            hyper = self.hyperparameters(members)
            n_members = members.shape[0]
            total = np.zeros(n_members)
            for distances, keys in self._groups:
                index = self.train_index[keys[0]]
                scales = [self.problem.target_scales[key] for key in keys]
                residuals = np.concatenate([
                    (self.problem.observed[key][index] - outputs[key][:, index]) / scale for key, scale in zip(keys, scales)
                ])
                amplitude = np.concatenate([hyper[key].amplitude / scale for key, scale in zip(keys, scales)])
                length_scales = np.concatenate([hyper[key].length_scales for key in keys])
                noise = np.concatenate([hyper[key].noise_std / scale for key, scale in zip(keys, scales)])
                values = log_marginal_likelihood(residuals, distances, amplitude, length_scales, noise)
                total += values.reshape(len(keys), n_members).sum(axis=0) - index.size * np.log(scales).sum()
            log_likelihood[inside] = np.where(np.isfinite(total), total, -np.inf)
        return log_prior, log_likelihood

    def log_posterior(self, batch: np.ndarray) -> np.ndarray:
        """Unnormalised log posterior ``log p(θ, φ) + log L``, ``ndarray[n]``."""
        log_prior, log_likelihood = self.evaluate(batch)
        return log_prior + log_likelihood

    def initial_ensemble(
        self, theta: np.ndarray, residual_std: dict[str, float], n_walkers: int, random_state: np.random.RandomState,
        theta_covariance: np.ndarray | None = None,
    ) -> np.ndarray:
        """Walkers around a point estimate, for the start of a sampler (``docs/calibration.md``).

        θ: ``theta`` + N(0, (1 % of the prior width)²), or with ``theta_covariance`` (the point
        fit's Laplace covariance, physical units) ``theta`` + D·z, z ~ N(0, R), R its correlation
        matrix and D its standard errors capped at 10 % of the prior width (the plain ball where a
        standard error is zero). Per target log σ_n and log σ_f near the point fit's residual
        standard deviation, log ℓ near log 0.1, each with N(0, 0.1²) jitter; all clipped a hair
        inside the prior bounds.

        :returns: ``ndarray[n_walkers, n_dim]``.
        """
        centre = [np.asarray(theta, dtype=float)]
        for key in self.problem.target_keys:
            relative = max(residual_std[key] / self.problem.target_scales[key], 1e-12)
            centre.append([np.log(relative)] + [np.log(0.1)] * self.n_inputs + [np.log(relative)])
        centre = np.concatenate([np.ravel(c) for c in centre])
        width = self.upper - self.lower
        spread = np.concatenate([0.01 * width[: self.n_theta], np.full(self.n_dim - self.n_theta, 0.1)])
        walkers = centre + spread * random_state.standard_normal((n_walkers, self.n_dim))
        if theta_covariance is not None:
            covariance = np.asarray(theta_covariance, dtype=float)
            if covariance.shape != (self.n_theta, self.n_theta):
                raise ValueError(f"theta_covariance has shape {covariance.shape}, expected ({self.n_theta}, {self.n_theta})")
            standard_error = np.sqrt(np.diag(covariance))
            if not np.all(np.isfinite(covariance)) or np.any(standard_error <= 0.0):
                theta_covariance = None  # exact residuals (zero standard errors): the plain ball
        if theta_covariance is not None:
            correlation = covariance / np.outer(standard_error, standard_error)
            values, vectors = np.linalg.eigh(correlation)
            root = vectors * np.sqrt(np.clip(values, 0.0, None))
            z = random_state.standard_normal((n_walkers, self.n_theta)) @ root.T
            walkers[:, : self.n_theta] = centre[: self.n_theta] + z * np.minimum(standard_error, 0.1 * width[: self.n_theta])
        margin = 1e-6 * width
        return np.clip(walkers, self.lower + margin, self.upper - margin)
