"""Matérn 3/2 Gaussian process: covariance, log marginal likelihood and conditional, batched::

    k(x, x') = σ_f² (1 + √3 r) exp(−√3 r),    r = sqrt(Σ_i ((x_i − x'_i) / ℓ_i)²)
    log p(y) = −½ yᵀ (K + σ_n² I)⁻¹ y − Σ log L_ii − (n/2) log 2π,    K + σ_n² I = L Lᵀ
    μ* = K*ᵀ (K + σ_n² I)⁻¹ y,    Σ* = K** − K*ᵀ (K + σ_n² I)⁻¹ K*

Every function takes a batch of ``s`` hyperparameter sets: a batched Cholesky per chunk of
:data:`CHUNK_SIZE` sets, or for one input the exact O(n) state-space (Kalman) form of the process
(Hartikainen & Särkkä 2010). Sources: Rasmussen & Williams 2006, Eqs. 2.30, 4.17; Bjørnskov, Jradi &
Wetter, Sec. 4, Eqs. 4–22. The state-space equations and the costs: ``docs/calibration.md``.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

__all__ = [
    "CHUNK_SIZE", "STATE_SPACE_MIN_WORK", "matern32", "InputDistances", "log_marginal_likelihood", "conditional",
]

#: Hyperparameter sets handled per batched factorisation.
CHUNK_SIZE = 32
#: ``s · n²`` from which ``method="auto"`` takes the state-space path, faster there than the dense one
#: (the costs: ``docs/calibration.md``, *The Matérn-3/2 GP discrepancy*).
STATE_SPACE_MIN_WORK = 4e5
_SQRT3 = np.sqrt(3.0)


def matern32(scaled_distance: np.ndarray) -> np.ndarray:
    """Matérn 3/2 correlation ``(1 + √3 r) exp(−√3 r)`` of the scaled distance ``r ≥ 0``."""
    z = _SQRT3 * np.asarray(scaled_distance, dtype=float)
    return (1.0 + z) * np.exp(-z)


class InputDistances:
    """Per-input absolute differences between two input sets, computed once and reused.

    :param x1: ``ndarray[n1, d]`` (or ``[n1]`` for one input).
    :param x2: ``ndarray[n2, d]``; None for ``x1`` against itself.
    """

    def __init__(self, x1: np.ndarray, x2: np.ndarray | None = None) -> None:
        a = np.asarray(x1, dtype=float)
        a = a[:, None] if a.ndim == 1 else a
        b = a if x2 is None else np.asarray(x2, dtype=float)
        b = b[:, None] if b.ndim == 1 else b
        if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
            raise ValueError(f"inputs of shapes {a.shape} and {b.shape}: expected (n1, d) and (n2, d)")
        self.shape = (a.shape[0], b.shape[0])
        self.n_inputs = a.shape[1]
        differences = np.abs(a[:, None, :] - b[None, :, :])  # n1, n2, d
        self._sorted: tuple[np.ndarray, np.ndarray] | None = None
        if self.n_inputs == 1 and x2 is None:
            order = np.argsort(a[:, 0], kind="stable")
            self._sorted = (order, np.diff(a[order, 0]))  # for the state-space likelihood
        if self.n_inputs == 1:
            distance = differences[..., 0]
            rounded = np.round(distance / max(float(distance.max()), 1e-300), 12)
            _, first, inverse = np.unique(rounded, return_index=True, return_inverse=True)
            self._unique = distance.ravel()[first]
            self._inverse = inverse.reshape(self.shape)
        else:
            self._squared = np.moveaxis(differences**2, -1, 0)  # d, n1, n2

    def covariance(self, amplitude: np.ndarray, length_scales: np.ndarray) -> np.ndarray:
        """``k`` for a batch of hyperparameter sets.

        :param amplitude: σ_f, ``ndarray[s]``.
        :param length_scales: ℓ, ``ndarray[s, d]``, in the units of the inputs.
        :returns: ``ndarray[s, n1, n2]``.
        """
        amplitude = np.asarray(amplitude, dtype=float)
        length_scales = np.asarray(length_scales, dtype=float)
        if length_scales.shape != (amplitude.shape[0], self.n_inputs):
            raise ValueError(
                f"length_scales has shape {length_scales.shape}, expected ({amplitude.shape[0]}, {self.n_inputs})"
            )
        variance = (amplitude**2)[:, None, None]
        if self.n_inputs == 1:
            values = matern32(self._unique[None, :] / length_scales)
            return variance * np.take(values, self._inverse, axis=1)
        scaled = np.einsum("sd,dij->sij", 1.0 / length_scales**2, self._squared)
        return variance * matern32(np.sqrt(scaled, out=scaled))


def _factor(train: InputDistances, amplitude, length_scales, noise_std):
    """Batched Cholesky factors of ``K + σ_n² I``; ``ok`` marks the sets where it exists."""
    covariance = train.covariance(amplitude, length_scales)
    diagonal = np.einsum("sii->si", covariance)
    diagonal += (np.asarray(noise_std, dtype=float) ** 2)[:, None]
    try:
        return np.linalg.cholesky(covariance), np.ones(covariance.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        factors = np.zeros_like(covariance)
        ok = np.zeros(covariance.shape[0], dtype=bool)
        for i, matrix in enumerate(covariance):
            try:
                factors[i] = np.linalg.cholesky(matrix)
                ok[i] = True
            except np.linalg.LinAlgError:
                factors[i] = np.eye(matrix.shape[0])
        return factors, ok


def _chunks(n: int):
    for start in range(0, n, CHUNK_SIZE):
        yield slice(start, min(start + CHUNK_SIZE, n))


def log_marginal_likelihood(
    residuals: np.ndarray,
    train: InputDistances,
    amplitude: np.ndarray,
    length_scales: np.ndarray,
    noise_std: np.ndarray,
    method: str = "auto",
) -> np.ndarray:
    """``log N(y | 0, K + σ_n² I)`` per set; −inf where ``K + σ_n² I`` is not positive definite.

    :param method: ``"dense"`` (Cholesky), ``"state_space"`` (O(n) filter, one input only) or
        ``"auto"``: the state space for one input when ``s · n² ≥`` :data:`STATE_SPACE_MIN_WORK`.

    :param residuals: ``ndarray[s, n]``, one residual vector per hyperparameter set.
    :param train: distances of the ``n`` inputs to themselves.
    :param amplitude: σ_f, ``ndarray[s]``; ``length_scales``: ``ndarray[s, d]``; ``noise_std``: σ_n, ``ndarray[s]``.
    :returns: ``ndarray[s]``.
    """
    residuals = np.asarray(residuals, dtype=float)
    amplitude, length_scales, noise_std = (np.asarray(v, dtype=float) for v in (amplitude, length_scales, noise_std))
    n_sets, n = residuals.shape
    if train.shape != (n, n):
        raise ValueError(f"residuals have {n} points but the training distances are {train.shape}")
    if length_scales.shape != (n_sets, train.n_inputs):
        raise ValueError(f"length_scales has shape {length_scales.shape}, expected ({n_sets}, {train.n_inputs})")
    if method not in ("auto", "dense", "state_space"):
        raise ValueError(f"method={method!r}: expected 'auto', 'dense' or 'state_space'")
    if method == "state_space" and train._sorted is None:
        raise ValueError("the state-space likelihood needs one input, given against itself")
    if train._sorted is not None and (
        method == "state_space" or (method == "auto" and n_sets * n * n >= STATE_SPACE_MIN_WORK)
    ):
        return _state_space_log_likelihood(residuals, train._sorted, amplitude, length_scales[:, 0], noise_std)
    result = np.empty(n_sets)
    for part in _chunks(n_sets):
        factors, ok = _factor(train, amplitude[part], length_scales[part], noise_std[part])
        whitened = solve_triangular(factors, residuals[part, :, None], lower=True, check_finite=False)[..., 0]
        log_det_half = np.log(np.einsum("sii->si", factors)).sum(axis=1)
        value = -0.5 * np.sum(whitened**2, axis=1) - log_det_half - 0.5 * n * np.log(2.0 * np.pi)
        result[part] = np.where(ok, value, -np.inf)
    return result


def _state_space_log_likelihood(residuals, sorted_inputs, amplitude, length_scale, noise_std) -> np.ndarray:
    """Kalman-filter log marginal likelihood of a 1-D Matérn 3/2 GP (``docs/calibration.md``), ``ndarray[s]``."""
    order, gaps = sorted_inputs
    y = residuals[:, order].T  # n, s: one contiguous row per step
    lam = _SQRT3 / np.asarray(length_scale, dtype=float)
    var = np.asarray(amplitude, dtype=float) ** 2
    slope_var = lam**2 * var
    noise_var = np.asarray(noise_std, dtype=float) ** 2
    lam_gap = gaps[:, None] * lam[None, :]
    decay = np.exp(-lam_gap)
    phi00, phi01 = decay * (1.0 + lam_gap), decay * gaps[:, None]
    phi10, phi11 = -decay * lam[None, :] * lam_gap, decay * (1.0 - lam_gap)
    m0, m1 = np.zeros_like(lam), np.zeros_like(lam)
    p00, p01, p11 = var.copy(), np.zeros_like(lam), slope_var.copy()
    quadratic, log_det = np.zeros_like(lam), np.zeros_like(lam)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(y.shape[0]):
            if k:
                f00, f01, f10, f11 = phi00[k - 1], phi01[k - 1], phi10[k - 1], phi11[k - 1]
                m0, m1 = f00 * m0 + f01 * m1, f10 * m0 + f11 * m1
                d00, d11 = p00 - var, p11 - slope_var  # P − P∞ (off-diagonal of P∞ is 0)
                t00, t01 = f00 * d00 + f01 * p01, f00 * p01 + f01 * d11
                t10, t11 = f10 * d00 + f11 * p01, f10 * p01 + f11 * d11
                p00 = t00 * f00 + t01 * f01 + var
                p01 = t00 * f10 + t01 * f11
                p11 = t10 * f10 + t11 * f11 + slope_var
            innovation_var = p00 + noise_var
            innovation = y[k] - m0
            quadratic += innovation**2 / innovation_var
            log_det += np.log(innovation_var)
            gain0, gain1 = p00 / innovation_var, p01 / innovation_var
            m0, m1 = m0 + gain0 * innovation, m1 + gain1 * innovation
            p11 = p11 - gain1 * p01
            p01 = p01 * (1.0 - gain0)
            p00 = p00 * (1.0 - gain0)
        value = -0.5 * (quadratic + log_det + y.shape[0] * np.log(2.0 * np.pi))
    return np.where(np.isfinite(value), value, -np.inf)


def conditional(
    residuals: np.ndarray,
    train: InputDistances,
    cross: InputDistances,
    test: InputDistances,
    amplitude: np.ndarray,
    length_scales: np.ndarray,
    noise_std: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the discrepancy δ at test inputs given training residuals (per set).

    :param residuals: ``ndarray[s, n]`` at the training inputs.
    :param train: training inputs against themselves (n × n).
    :param cross: training against test inputs (n × m).
    :param test: test inputs against themselves (m × m).
    :returns: ``mean ndarray[s, m]`` and ``covariance ndarray[s, m, m]`` (without the noise σ_n²).
    :raises ValueError: when ``K + σ_n² I`` is not positive definite for a set.
    """
    residuals = np.asarray(residuals, dtype=float)
    n_sets, n = residuals.shape
    m = test.shape[0]
    if train.shape != (n, n) or cross.shape != (n, m) or test.shape != (m, m):
        raise ValueError(f"distance shapes {train.shape}, {cross.shape}, {test.shape} do not fit n={n}, m={m}")
    mean = np.empty((n_sets, m))
    covariance = np.empty((n_sets, m, m))
    for part in _chunks(n_sets):
        factors, ok = _factor(train, amplitude[part], length_scales[part], noise_std[part])
        if not ok.all():
            raise ValueError("K + σ_n² I is not positive definite for a hyperparameter set")
        k_cross = cross.covariance(amplitude[part], length_scales[part])
        v = solve_triangular(factors, k_cross, lower=True, check_finite=False)  # L⁻¹ K*
        whitened = solve_triangular(factors, residuals[part, :, None], lower=True, check_finite=False)  # L⁻¹ y
        mean[part] = np.einsum("snm,sn->sm", v, whitened[..., 0])
        covariance[part] = test.covariance(amplitude[part], length_scales[part]) - np.einsum(
            "snm,snk->smk", v, v
        )
    return mean, covariance
