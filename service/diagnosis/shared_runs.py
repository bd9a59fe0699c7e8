"""The catalog's candidates simulated together: members of runs of one model that holds all their effects.

A run of the vectorised simulator costs about the same for a few members as for a hundred (its time
loop's per-step overhead dominates, ``docs/benchmarks.md``), and each candidate's refit is a chain of
simulate calls. :class:`SharedRuns` evaluates candidates side by side, one thread each, and gathers
their calls (:class:`~service.calibration.lockstep.GatheredCalls`) into one run per window of a
*shared model*: the base model with every effect of the group spliced in. A candidate's θ enters it
with the other effects at their null, where each is the identity, so a member's outputs are those of
the candidate's own model (tested; to rounding: numpy's stacked matrix product rounds a row
differently in ensembles of different sizes); a drift candidate's factors ride along (factor 1
for the other members), and so does its warm-up (one run per warm-up length). Effects whose host
keeps its readings (a leak: the position feedback reads the command) are spliced last, so an effect
spliced on the same port after them sees the feedback its own model gives it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import NamedTuple, TypeVar

import numpy as np

from service.calibration.lockstep import GatheredCalls, split_rows
from service.calibration.model_data import ModelData
from service.graph.store import GraphStore
from service.matching.signature import Signature
from service.model.assembled_model import AssembledModel
from service.model.assembly import assemble
from service.model.effect_splicing import EffectRequest
from service.model.simulator import SimulationResult

__all__ = ["OwnRuns", "SharedRuns", "shared_model"]

Main = TypeVar("Main")
Other = TypeVar("Other")


def shared_model(store: GraphStore, model_name: str, library: Mapping[str, Signature],
                 effects: Sequence[EffectRequest]) -> AssembledModel:
    """The model with every effect of ``effects`` spliced in, those that leave their host's readings
    unchanged last (module docstring)."""
    def keeps_readings(request: EffectRequest) -> bool:
        splice = library[request.effect].splice
        return bool(splice is not None and splice.readings_unchanged)

    return assemble(store, model_name, library=library, extra_effects=sorted(effects, key=keeps_readings))


class _Run(NamedTuple):
    """One candidate's simulate request, in the shared model's θ."""

    window: slice
    warmup_s: float
    theta: np.ndarray
    fixed: tuple
    record: tuple | None
    factors: dict[str, np.ndarray]


class SharedRuns:
    """Simulate calls of ``n_candidates`` concurrent candidate evaluations, gathered into runs of
    ``shared`` (:class:`ModelData` of :func:`shared_model`); each candidate asks through the
    :class:`ModelData` of :meth:`member_data`, and calls :meth:`leave` when it ends."""

    def __init__(self, shared: ModelData, n_candidates: int):
        self.shared = shared
        refs = shared.model.estimated_parameters
        self._column = {ref.key: j for j, ref in enumerate(refs)}
        self._null = np.array([ref.spec.null if ref.spec.null is not None else ref.spec.default for ref in refs])
        self._calls = GatheredCalls(self._batch, n_candidates)
        self._by_warmup = {shared.warmup_s: shared}

    def seat(self, index: int) -> _Seat:
        """Candidate number ``index``'s access to the shared runs (:class:`OwnRuns`' interface)."""
        return _Seat(self, index)

    def member_data(self, model: AssembledModel, caller: tuple[int, int]) -> ModelData:
        """``model`` (a candidate's: the base with one of the shared model's effects, or a drift)
        bound to the shared data, its runs made by the shared model as caller ``caller``."""
        missing = [ref.key for ref in model.estimated_parameters
                   if ref.key not in self._column and not any(d.size_key == ref.key for d in model.drifts)]
        if missing:
            raise ValueError(f"the shared model lacks the candidate's parameters {', '.join(missing)}")
        md = self.shared
        return _MemberData(model, md.data, md.substeps, md.compared, runs=self, caller=caller)

    def join(self) -> None:
        """One more concurrent caller."""
        self._calls.join()

    def leave(self) -> None:
        """One caller ended."""
        self._calls.leave()

    def run(self, caller: tuple[int, int], member: ModelData, window: slice, theta: np.ndarray,
            fixed: Mapping[str, float], record, factors: Mapping[str, np.ndarray]) -> SimulationResult:
        """``member``'s run of ``window`` for θ rows in its model's order, made by the shared model
        (after the member's own warm-up)."""
        model = member.model
        columns = [(j, self._column[ref.key]) for j, ref in enumerate(model.estimated_parameters)
                   if ref.key in self._column]
        shared_theta = np.repeat(self._null[None, :], theta.shape[0], axis=0)
        shared_theta[:, [c for _, c in columns]] = theta[:, [j for j, _ in columns]]
        request = _Run(window, member.warmup_s, shared_theta, tuple(sorted(fixed.items())),
                       None if record is None else tuple(record), dict(factors))
        return self._calls.ask(caller, request)

    def _batch(self, requests: list[_Run]) -> list[SimulationResult]:
        """One run of the shared model per (window, warm-up, fixed values, recorded outputs) among ``requests``."""
        groups: dict[tuple, list[int]] = {}
        for i, request in enumerate(requests):
            key = (request.window.start, request.window.stop, request.warmup_s, request.fixed, request.record)
            groups.setdefault(key, []).append(i)
        results: list[SimulationResult | None] = [None] * len(requests)
        for indices in groups.values():
            first = requests[indices[0]]
            if first.warmup_s not in self._by_warmup:
                self._by_warmup[first.warmup_s] = replace(self.shared, warmup_s=first.warmup_s)
            shared = self._by_warmup[first.warmup_s]
            n_steps = first.window.stop - first.window.start + shared.warmup_steps
            keys = sorted({key for i in indices for key in requests[i].factors})
            factors = {key: np.vstack([requests[i].factors.get(key, np.ones((requests[i].theta.shape[0], n_steps)))
                                       for i in indices]) for key in keys}
            result = shared.run(first.window, np.vstack([requests[i].theta for i in indices]), dict(first.fixed),
                                record=first.record, factors=factors or None)
            rows = split_rows(result.outputs, [requests[i].theta.shape[0] for i in indices])
            for i, outputs in zip(indices, rows):
                results[i] = SimulationResult(outputs, result.step_s)
        return results


@dataclass
class _MemberData(ModelData):
    """A candidate's :class:`ModelData` whose runs :class:`SharedRuns` makes."""

    runs: SharedRuns | None = None
    caller: tuple[int, int] = (0, 0)

    def _simulate(self, window: slice, theta: np.ndarray, fixed: Mapping[str, float] | None,
                  record: Sequence[tuple[str, str]] | None,
                  factors: Mapping[str, np.ndarray] | None) -> SimulationResult:
        return self.runs.run(self.caller, self, window, theta, dict(fixed or {}), record, dict(factors or {}))


class OwnRuns:
    """A candidate's simulations on its own model's simulator, one after the other."""

    def __init__(self, data, substeps: int, compared: np.ndarray | None):
        self._data, self._substeps, self._compared = data, substeps, compared

    def data_for(self, model: AssembledModel) -> ModelData:
        """``model`` bound to the data."""
        return ModelData(model, self._data, self._substeps, self._compared)

    def alongside(self, model: AssembledModel, main: Callable[[], Main],
                  others: Sequence[Callable[[ModelData], Other]]) -> tuple[Main, list[Other]]:
        """``main()`` and each of ``others`` given ``model``'s data (independent fits): here in turn."""
        return main(), [other(self.data_for(model)) for other in others]


class _Seat:
    """Candidate ``index``'s access to :class:`SharedRuns`: its main thread asks as caller
    (index, 0), the fits it runs alongside as (index, 1), (index, 2), …"""

    def __init__(self, runs: SharedRuns, index: int):
        self._runs, self._index = runs, index

    def data_for(self, model: AssembledModel) -> ModelData:
        return self._runs.member_data(model, (self._index, 0))

    def alongside(self, model: AssembledModel, main: Callable[[], Main],
                  others: Sequence[Callable[[ModelData], Other]]) -> tuple[Main, list[Other]]:
        """``main()`` in this thread and each of ``others`` in its own, all asking for runs at once."""
        if not others:
            return main(), []
        runs = self._runs

        def child(other: Callable[[ModelData], Other], data: ModelData) -> Other:
            try:
                return other(data)
            finally:
                runs.leave()

        seats = [runs.member_data(model, (self._index, k)) for k in range(1, len(others) + 1)]
        with ThreadPoolExecutor(max_workers=len(others)) as pool:
            futures = []
            for other, data in zip(others, seats):
                runs.join()  # counted before it can ask, and only once it will
                futures.append(pool.submit(child, other, data))
            try:
                first = main()
            finally:
                runs.leave()  # while this thread waits for the others, batches do not wait for it
                try:
                    done = [future.result() for future in futures]
                finally:
                    runs.join()
        return first, done
