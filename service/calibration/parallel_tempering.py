"""Parallel-tempering ensemble MCMC, every temperature evaluated in one batch, stopped by the IAT rule.

``n_temperatures`` affine-invariant ensembles (Goodman & Weare 2010) with emcee's red–blue proposals,
chain storage and IAT; walkers swap between neighbouring temperatures (Earl & Deem 2005): the chain
at β targets ``p(θ) L(θ)^β``; a swap of β_c with β_h < β_c is accepted with
``min(1, exp((β_c − β_h)(log L_j − log L_i)))``. Ladder: geometric, ``T_{i+1}/T_i = 1 + 2 √(ln 4 /
n_dim)``, optionally adapted (Vousden, Farr & Mandel 2016). The run stops when the β = 1 chain is
``iat_multiple`` (20) × its IAT τ long and τ changed by less than ``iat_rtol``; burn-in 2τ, thinning
τ/2. Why and how: ``docs/calibration.md``, *Parallel tempering* and *Convergence and the IAT*.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import emcee
import numpy as np
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from sklearn.utils import check_random_state

from service.errors import CalibrationError

__all__ = ["ParallelTemperingSampler", "Convergence", "geometric_betas"]

LogPriorAndLikelihood = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def geometric_betas(n_temperatures: int, n_dim: int, max_temperature: float | None = None) -> np.ndarray:
    """Inverse temperatures, β = 1 first, geometrically spaced in T up to ``max_temperature``."""
    if n_temperatures < 1:
        raise CalibrationError(f"n_temperatures={n_temperatures}: need at least 1")
    if max_temperature is None:
        ratio = 1.0 + 2.0 * np.sqrt(np.log(4.0) / n_dim)
        return ratio ** -np.arange(n_temperatures, dtype=float)
    if n_temperatures > 1 and not max_temperature > 1.0:
        raise CalibrationError(f"max_temperature={max_temperature}: must exceed 1")
    return max_temperature ** -(np.arange(n_temperatures) / max(n_temperatures - 1, 1))


def _nan_to_minus_inf(values, shape: tuple[int, ...]) -> np.ndarray:
    values = np.asarray(values, dtype=float).reshape(shape)
    return np.where(np.isnan(values), -np.inf, values)


@dataclass(frozen=True)
class Convergence:
    """How a run ended: ``iat`` the last τ estimate in steps; ``burn_in`` and ``thin`` derived from it."""

    converged: bool
    n_steps: int
    iat: float
    iat_history: tuple[float, ...]
    burn_in: int
    thin: int


class ParallelTemperingSampler:
    """Tempered stretch-move ensembles, swaps after every step, one batched evaluation per half-step.

    :param log_prior_and_likelihood: ``coords ndarray[n, n_dim] → (log_prior ndarray[n],
        log_likelihood ndarray[n])``; −inf log prior outside the support.
    :param n_walkers: walkers per temperature, even, at least ``2 · n_dim``.
    :param betas: inverse temperatures, 1 first then decreasing (default :func:`geometric_betas`).
    :param adapt_ladder: adapt the intermediate temperatures (Vousden et al. 2016).
    :param adaptation_lag: t₀; ``adaptation_time``: ν (ptemcee's defaults).
    :param stretch_scale: the stretch move's ``a`` (when ``moves`` is None).
    :param moves: an :class:`emcee.moves.RedBlueMove` splitting the ensemble in two (stretch,
        differential evolution, walk), or ``[(move, weight), …]`` drawn per step with probability ∝
        weight (emcee's convention); None: the stretch move.
    :param random_state: seed, ``numpy.random.RandomState`` or None; a seeded run is reproducible.

    After :meth:`run`: ``backend`` (the β = 1 chain), ``betas``, ``acceptance_fraction``
    (per temperature), ``swap_acceptance_fraction`` (per neighbouring pair, coldest pair first),
    ``coords``, ``log_prior``, ``log_likelihood`` (the last state of every temperature).
    """

    def __init__(
        self,
        log_prior_and_likelihood: LogPriorAndLikelihood,
        n_walkers: int,
        n_dim: int,
        betas: np.ndarray | None = None,
        adapt_ladder: bool = True,
        adaptation_lag: float = 10000.0,
        adaptation_time: float = 100.0,
        stretch_scale: float = 2.0,
        moves: emcee.moves.RedBlueMove | list[tuple[emcee.moves.RedBlueMove, float]] | None = None,
        random_state: int | np.random.RandomState | None = None,
    ) -> None:
        if n_walkers % 2 or n_walkers < 2 * n_dim:
            raise CalibrationError(f"n_walkers={n_walkers}: need an even number of at least 2 · n_dim = {2 * n_dim}")
        self.log_prior_and_likelihood = log_prior_and_likelihood
        self.n_walkers = n_walkers
        self.n_dim = n_dim
        self.betas = geometric_betas(4, n_dim) if betas is None else np.array(betas, dtype=float)
        if self.betas[0] != 1.0 or np.any(np.diff(self.betas) >= 0.0) or self.betas[-1] <= 0.0:
            raise CalibrationError(f"betas {self.betas}: need 1 first, strictly decreasing, positive")
        self.adapt_ladder = adapt_ladder
        self.adaptation_lag = adaptation_lag
        self.adaptation_time = adaptation_time
        self.stretch_scale = stretch_scale
        self.moves = moves
        self.random_state = random_state

    @property
    def n_temperatures(self) -> int:
        return self.betas.size

    def _evaluate(self, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One batched call for ``coords ndarray[T, m, n_dim]``; NaN becomes −inf."""
        shape = coords.shape[:2]
        log_prior, log_likelihood = self.log_prior_and_likelihood(coords.reshape(-1, self.n_dim))
        return _nan_to_minus_inf(log_prior, shape), _nan_to_minus_inf(log_likelihood, shape)

    def _tempered(self, log_prior: np.ndarray, log_likelihood: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            value = log_prior + self.betas[:, None] * log_likelihood
        return np.where(np.isfinite(log_prior) & np.isfinite(log_likelihood), value, -np.inf)

    def _step(self) -> np.ndarray:
        """One red–blue update of every temperature (one move for all); returns ``accepted bool[T, W]``."""
        move = self._moves[0] if len(self._moves) == 1 else self._moves[
            self._random.choice(len(self._moves), p=self._move_weights)]
        move.setup(self.coords[0])  # as emcee's RedBlueMove.propose does (DE sets its γ₀ from n_dim)
        split = np.arange(self.n_walkers) % 2
        self._random.shuffle(split)
        accepted = np.zeros((self.n_temperatures, self.n_walkers), dtype=bool)
        for half in (0, 1):
            moving = np.flatnonzero(split == half)
            others = np.flatnonzero(split != half)
            proposals = [
                move.get_proposal(self.coords[t, moving], [self.coords[t, others]], self._random)
                for t in range(self.n_temperatures)
            ]
            q = np.stack([p[0] for p in proposals])
            log_factor = np.stack([p[1] for p in proposals])
            new_prior, new_likelihood = self._evaluate(q)
            old = self._tempered(self.log_prior[:, moving], self.log_likelihood[:, moving])
            log_alpha = log_factor + self._tempered(new_prior, new_likelihood) - old
            accept = log_alpha > np.log(self._random.rand(*log_alpha.shape))
            t_index, w_index = np.nonzero(accept)
            walkers = moving[w_index]
            self.coords[t_index, walkers] = q[t_index, w_index]
            self.log_prior[t_index, walkers] = new_prior[t_index, w_index]
            self.log_likelihood[t_index, walkers] = new_likelihood[t_index, w_index]
            accepted[t_index, walkers] = True
        return accepted

    def _swap(self) -> np.ndarray:
        """Propose exchanges between every neighbouring pair, hottest pair first; accepted fraction per pair."""
        fraction = np.zeros(self.n_temperatures - 1)
        for hot in range(self.n_temperatures - 1, 0, -1):
            cold = hot - 1
            partner = self._random.permutation(self.n_walkers)
            log_alpha = (self.betas[cold] - self.betas[hot]) * (
                self.log_likelihood[hot, partner] - self.log_likelihood[cold]
            )
            accept = log_alpha > np.log(self._random.rand(self.n_walkers))
            c, h = np.flatnonzero(accept), partner[accept]
            for array in (self.coords, self.log_prior, self.log_likelihood):
                array[cold, c], array[hot, h] = array[hot, h].copy(), array[cold, c].copy()
            fraction[cold] = accept.mean()
        return fraction

    def _adapt(self, swap_fraction: np.ndarray, step: int) -> None:
        """Vousden et al. (2016) ladder update; β = 1 and the hottest β stay fixed."""
        if not self.adapt_ladder or self.n_temperatures < 3:
            return
        kappa = self.adaptation_lag / (step + self.adaptation_lag) / self.adaptation_time
        temperatures = 1.0 / self.betas
        gaps = np.diff(temperatures[:-1]) * np.exp(kappa * (swap_fraction[:-1] - swap_fraction[1:]))
        middle = temperatures[0] + np.cumsum(gaps)
        if middle[-1] < temperatures[-1]:  # keep the ladder ordered below the fixed hottest temperature
            self.betas[1:-1] = 1.0 / middle

    def run(
        self,
        initial: np.ndarray,
        max_steps: int,
        check_interval: int = 100,
        iat_multiple: float = 20.0,
        iat_rtol: float = 0.05,
        progress: bool = False,
        on_check: Callable[[str], None] | None = None,
    ) -> Convergence:
        """Sample from ``initial`` until the 20 × IAT rule holds or ``max_steps`` is reached;
        ``on_check`` hears after each IAT check how far the chain is (a job's progress).

        :param initial: ``ndarray[n_walkers, n_dim]`` (all temperatures start alike) or
            ``ndarray[n_temperatures, n_walkers, n_dim]``; every walker with finite posterior.
        :raises ValueError: for a wrong shape.
        :raises CalibrationError: bad moves, or a walker with zero posterior probability.
        """
        self._random = check_random_state(self.random_state)
        moves = self.moves if self.moves is not None else emcee.moves.StretchMove(a=self.stretch_scale)
        pairs = moves if isinstance(moves, (list, tuple)) else [(moves, 1.0)]
        self._moves = [move for move, _ in pairs]
        weights = np.array([weight for _, weight in pairs], dtype=float)
        if not self._moves or np.any(weights <= 0.0):
            raise CalibrationError(f"moves {moves!r}: need at least one move and positive weights")
        split_in_more = [type(m).__name__ for m in self._moves if getattr(m, "nsplits", 2) != 2]
        if split_in_more:
            raise CalibrationError(f"moves {', '.join(split_in_more)} split the ensemble in more than two; "
                                   "this sampler's red–blue update takes two-way moves (stretch, DE, walk)")
        self._move_weights = weights / weights.sum()
        initial = np.asarray(initial, dtype=float)
        shape = (self.n_temperatures, self.n_walkers, self.n_dim)
        if initial.shape == shape[1:]:
            initial = np.broadcast_to(initial, shape)
        if initial.shape != shape:
            raise ValueError(f"initial has shape {initial.shape}, expected {shape[1:]} or {shape}")
        self.coords = initial.copy()
        self.log_prior, self.log_likelihood = self._evaluate(self.coords)
        bad = np.argwhere(~np.isfinite(self._tempered(self.log_prior, self.log_likelihood)))
        if bad.size:
            t, w = bad[0]
            raise CalibrationError(f"initial walker {w} at temperature index {t} has zero posterior probability")
        self.backend = emcee.backends.Backend()
        self.backend.reset(self.n_walkers, self.n_dim)
        accepted_total = np.zeros(self.n_temperatures)
        swapped_total = np.zeros(self.n_temperatures - 1)
        history: list[float] = []
        converged, step = False, 0
        with _ProgressDisplay(progress, max_steps) as display:
            while step < max_steps and not converged:
                block = min(check_interval, max_steps - step)
                self.backend.grow(block, None)
                for _ in range(block):
                    accepted = self._step()
                    swap_fraction = self._swap()
                    step += 1
                    self._adapt(swap_fraction, step)
                    accepted_total += accepted.sum(axis=1)
                    swapped_total += swap_fraction
                    cold = emcee.State(self.coords[0], log_prob=self.log_prior[0] + self.log_likelihood[0])
                    self.backend.save_step(cold, accepted[0])
                    self.acceptance_fraction = accepted_total / (step * self.n_walkers)
                    self.swap_acceptance_fraction = swapped_total / step
                    display.update(step, history[-1] if history else np.nan, self)
                with np.errstate(invalid="ignore", divide="ignore"):  # a walker stuck so far: NaN, not converged
                    iat = float(np.max(emcee.autocorr.integrated_time(self.backend.get_chain(), tol=0, quiet=True)))
                previous = history[-1] if history else np.inf
                history.append(iat)
                finite = bool(np.isfinite(iat))
                converged = finite and step >= iat_multiple * iat and abs(iat - previous) < iat_rtol * iat
                target = min(max_steps, max(step, int(np.ceil(iat_multiple * iat)))) if finite else max_steps
                display.set_target(target)
                if on_check is not None:
                    on_check(f"sampling: step {step} of {target} expected (at most {max_steps}), IAT {iat:.0f}"
                             if finite else f"sampling: step {step} of at most {max_steps}, IAT not yet estimable")
        iat = history[-1]
        finite = bool(np.isfinite(iat))
        return Convergence(
            converged=converged,
            n_steps=step,
            iat=iat,
            iat_history=tuple(history),
            burn_in=min(int(np.ceil(2.0 * iat)), step - 1) if finite else step // 2,
            thin=max(1, int(iat / 2.0)) if finite else 1,
        )


class _ProgressDisplay:
    """A rich progress bar (steps, IAT, acceptance and swap rates, ETA); does nothing when disabled."""

    def __init__(self, enabled: bool, total: int) -> None:
        self.enabled = enabled
        self.total = total

    def __enter__(self) -> _ProgressDisplay:
        if self.enabled:
            self._progress = Progress(
                TextColumn("PT-MCMC"), BarColumn(), MofNCompleteColumn(),
                TextColumn("IAT {task.fields[iat]}  acc {task.fields[acceptance]}  swap {task.fields[swap]}"),
                TimeRemainingColumn(),
            )
            self._progress.__enter__()
            self._task = self._progress.add_task("sampling", total=self.total, iat="–", acceptance="–", swap="–")
        return self

    def update(self, step: int, iat: float, sampler: ParallelTemperingSampler) -> None:
        if self.enabled:
            self._progress.update(
                self._task, completed=step,
                iat="–" if not np.isfinite(iat) else f"{iat:.0f}",
                acceptance=f"{sampler.acceptance_fraction[0]:.2f}",
                swap=" ".join(f"{s:.2f}" for s in sampler.swap_acceptance_fraction) or "–",
            )

    def set_target(self, total: int) -> None:
        """The step count the run now expects to need (20 × IAT, capped by ``max_steps``): drives the ETA."""
        if self.enabled:
            self._progress.update(self._task, total=total)

    def __exit__(self, *exc) -> None:
        if self.enabled:
            self._progress.__exit__(*exc)
