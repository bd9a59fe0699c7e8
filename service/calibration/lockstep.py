"""Simulate calls shared: by concurrent fits, and by steps that know their members ahead.

A run of the vectorised simulator costs the same for 1 member as for ~60 (the per-step overhead of
its time loop dominates, ``docs/benchmarks.md``), so local fits from several starts, each in its own
thread, gain by waiting for each other: :class:`LockstepRuns` holds each call until every fit still
running has asked, then simulates all their members in one call and hands each its rows. A batch is
ordered by fit, so results do not depend on which thread asked first. Steps run one after the other
whose members are known before the first (a score test's differences, a probe's grid, a fit's
screened starts) share one call through :func:`with_prefetched_rows`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import Generic, TypeVar

import numpy as np

from service.calibration.problem import CalibrationProblem

__all__ = ["GatheredCalls", "LockstepRuns", "run_in_lockstep", "split_rows", "with_prefetched_rows"]

Key = TypeVar("Key")
Request = TypeVar("Request")
Result = TypeVar("Result")
Outputs = dict[str, np.ndarray]


def split_rows(outputs: Mapping[Key, np.ndarray], counts: Sequence[int]) -> list[dict[Key, np.ndarray]]:
    """``outputs`` (key → ``ndarray[n_rows, ...]``) cut into consecutive blocks of ``counts`` rows."""
    bounds = np.cumsum([0, *counts])
    return [{key: values[start:stop] for key, values in outputs.items()}
            for start, stop in zip(bounds[:-1], bounds[1:])]


class GatheredCalls(Generic[Request, Result]):
    """Calls of ``n_callers`` concurrent callers gathered into batches: a call blocks until every
    caller still running has asked (or left), then ``batch`` answers all requests at once (a list of
    requests ordered by caller → their results in that order); a caller calls :meth:`leave` when it
    ends, a new one :meth:`join` before it asks. Callers are named by comparable keys (the batch's order)."""

    def __init__(self, batch: Callable[[list[Request]], list[Result]], n_callers: int):
        self._batch = batch
        self._active = n_callers
        self._waiting: dict[Hashable, dict] = {}
        self._condition = threading.Condition()

    def ask(self, caller: Hashable, request: Request) -> Result:
        """``request``'s result, from the batch it joins."""
        slot = {"request": request}
        with self._condition:
            self._waiting[caller] = slot
            self._flush_when_all_wait()
            while "result" not in slot and "error" not in slot:
                self._condition.wait()
        if "error" in slot:
            raise slot["error"]
        return slot["result"]

    def join(self) -> None:
        """One more caller: batches wait for it too."""
        with self._condition:
            self._active += 1

    def leave(self) -> None:
        """One caller ended: the others no longer wait for it."""
        with self._condition:
            self._active -= 1
            self._flush_when_all_wait()

    def _flush_when_all_wait(self) -> None:
        if not self._waiting or len(self._waiting) < self._active:
            return
        batch = [self._waiting.pop(caller) for caller in sorted(self._waiting)]
        try:
            results = self._batch([slot["request"] for slot in batch])
        except BaseException as exc:  # every caller of the batch sees the failure
            for slot in batch:
                slot["error"] = exc
        else:
            for slot, result in zip(batch, results):
                slot["result"] = result
        self._condition.notify_all()


class LockstepRuns(GatheredCalls[np.ndarray, Outputs]):
    """``run(theta)`` of ``n_fits`` concurrent fits gathered into calls of ``simulate`` (θ rows →
    target → ``ndarray[n_rows, n_steps]``); a fit calls :meth:`leave` when it ends."""

    def __init__(self, simulate: Callable[[np.ndarray], Outputs], n_fits: int):
        def batch(thetas: list[np.ndarray]) -> list[Outputs]:
            return split_rows(simulate(np.vstack(thetas)), [theta.shape[0] for theta in thetas])
        super().__init__(batch, n_fits)

    def caller(self, fit: int) -> Callable[[np.ndarray], Outputs]:
        """The ``run`` of fit number ``fit``: blocks until its batch is simulated."""
        return lambda theta: self.ask(fit, np.atleast_2d(theta))


def run_in_lockstep(simulate: Callable[[np.ndarray], Outputs], starts: Sequence,
                    fit: Callable[[object, Callable[[np.ndarray], Outputs]], Result]) -> list[Result]:
    """``fit(start, run)`` for every start, concurrently, their ``run`` calls sharing simulate calls;
    the results in the order of ``starts`` (the first failure raised)."""
    lockstep = LockstepRuns(simulate, len(starts))

    def one(index: int) -> Result:
        try:
            return fit(starts[index], lockstep.caller(index))
        finally:
            lockstep.leave()

    with ThreadPoolExecutor(max_workers=len(starts)) as pool:
        return list(pool.map(one, range(len(starts))))


#: Rows of θ match a prefetched row when they agree to this share of each parameter's prior width (a
#: start's trip through the unit cube, or a clip into the bounds, moves it by a few ulps).
PREFETCH_MATCH = 1e-12


def with_prefetched_rows(problem: CalibrationProblem, *ensembles: np.ndarray) -> CalibrationProblem:
    """``problem`` whose simulate serves the rows of ``ensembles`` (θ ``ndarray[n, n_parameters]``,
    physical units), all simulated now in one call; a later call simulates, in one call, only the
    rows it lacks (and keeps none of them)."""
    width = problem.upper - problem.lower

    def key(row: np.ndarray) -> bytes:
        return np.round((row - problem.lower) / width / PREFETCH_MATCH).tobytes()

    theta = np.vstack(ensembles)
    outputs = problem.simulate(theta)
    kept = {key(row): {target: values[i] for target, values in outputs.items()} for i, row in enumerate(theta)}

    def simulate(theta: np.ndarray) -> dict[str, np.ndarray]:
        rows = [kept.get(key(row)) for row in theta]
        missing = [i for i, row in enumerate(rows) if row is None]
        if missing:
            fresh = problem.simulate(theta[missing])
            for j, i in enumerate(missing):
                rows[i] = {target: values[j] for target, values in fresh.items()}
        return {target: np.stack([row[target] for row in rows]) for target in rows[0]}

    return replace(problem, simulate=simulate)
