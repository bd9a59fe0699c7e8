"""Ensemble-vectorised fixed-step simulation of an assembled model.

:class:`Simulator` prepares what does not depend on θ once; :meth:`Simulator.run` steps all ensemble
members together (arrays of shape ``(n_ensemble,)``), components in topological order. A control
loop is broken by a one-step delay on the connection into a ``feedback`` port (else on a flow
connection, with a note); ``substeps`` runs the components at ``step_s / substeps`` with the boundary
series interpolated linearly. Memoryless components outside loops are evaluated over all steps at
once. Boundary inputs replay their measured series (NaN gaps held at the last value); ``warmup_steps``
lets dynamic components settle before the reported steps; ``factors`` make a parameter change over
time (a factor per member and data step). Times in s. Details: ``docs/assembly.md``.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from service.errors import InputError
from service.model.assembled_model import AssembledModel, Connection
from service.model.wiring import short_name

__all__ = ["Simulator", "SimulationResult", "simulate", "ComponentOrder", "component_order", "loop_substeps",
           "MAX_LOOP_STEP_S", "target_series", "held_over_gaps", "warmup_index"]

#: Longest internal step of a model with a closed control loop, s: at 2 minutes the case study's
#: heating loop is free of the sampling limit cycle over its whole prior (tests/components).
MAX_LOOP_STEP_S = 120.0


@dataclass
class SimulationResult:
    """``outputs[(component IRI, port)]``: ``ndarray[n_ensemble, n_steps]``."""

    outputs: dict[tuple[str, str], np.ndarray]
    step_s: float

    def target(self, component_iri: str) -> np.ndarray:
        """The virtual sensor's series (a measuring device's ``measured_value`` output)."""
        return self.outputs[(component_iri, "measured_value")]


_FLOW_UNITS = frozenset({"kg/s", "m3/s", "m3/h"})


def _strongly_connected(nodes: list[str], edges: Mapping[str, set[str]]) -> dict[str, int]:
    """Tarjan's algorithm (iterative): node → component id."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    comp: dict[str, int] = {}
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ())))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    comp[member] = index[node]
                    if member == node:
                        break
    return comp


def warmup_index(window: slice, warmup_steps: int, period_steps: int = 1) -> np.ndarray:
    """Indices of a series that give ``window`` preceded by ``warmup_steps`` steps of warm-up: the
    steps before the window, and before the series' first step its first ``period_steps`` repeated
    (the first day: the plant ran the same day before the log began, as EnergyPlus repeats its first
    day to warm up; 1: the first value held). Index ``k`` from ``window.start − warmup_steps`` to
    ``window.stop − 1``, a negative ``k`` replaced by ``k mod period_steps``."""
    index = np.arange(window.start - warmup_steps, window.stop)
    before = index < 0
    index[before] %= period_steps
    return index


def held_over_gaps(values: np.ndarray) -> np.ndarray:
    """``values`` with each NaN replaced by the last finite value before it (the first finite value
    before that one); at least one value must be finite."""
    finite = np.isfinite(values)
    index = np.where(finite, np.arange(values.size), 0)
    np.maximum.accumulate(index, out=index)
    held = values[index]
    first = int(np.argmax(finite))
    held[:first] = values[first]
    return held


class ComponentOrder(NamedTuple):
    """The components in stepping order, the delayed (loop-closing) connections, and a note per
    cycle without a feedback port saying where it was broken."""

    order: list[str]
    delayed: set[Connection]
    notes: list[str]


def component_order(model: AssembledModel) -> ComponentOrder:
    """The stepping order of ``model``'s components and the loop-closing connections (``docs/assembly.md``)."""
    nodes = sorted(model.components)
    edges: dict[str, set[str]] = defaultdict(set)
    for c in model.connections:
        edges[c.source].add(c.target)
    scc = _strongly_connected(nodes, edges)
    delayed: set[Connection] = set()
    for c in model.connections:
        port = model.components[c.target].model_class.port(c.target_port)
        if port.feedback and scc[c.source] == scc[c.target]:
            delayed.add(c)
    notes: list[str] = []
    while True:
        live = [c for c in model.connections if c not in delayed]
        indegree = {n: 0 for n in nodes}
        children: dict[str, list[str]] = defaultdict(list)
        for c in live:
            if c.source != c.target:
                indegree[c.target] += 1
                children[c.source].append(c.target)
        ready = sorted(n for n in nodes if indegree[n] == 0)
        order: list[str] = []
        while ready:
            node = ready.pop(0)
            order.append(node)
            for child in sorted(children[node]):
                indegree[child] -= 1
                if indegree[child] == 0:
                    ready.append(child)
                    ready.sort()
        self_loops = [c for c in live if c.source == c.target]
        if len(order) == len(nodes) and not self_loops:
            return ComponentOrder(order, delayed, notes)
        stuck = sorted(set(nodes) - set(order)) or [self_loops[0].target]
        candidates = sorted((c for c in live if c.target in stuck and (c.source in stuck or c.source == c.target)),
                            key=lambda c: (model.components[c.source].model_class.port(c.source_port).unit not in _FLOW_UNITS,
                                           c.target, c.target_port, c.source))
        chosen = candidates[0]
        delayed.add(chosen)
        source, target = (short_name(model.components[c].node) for c in (chosen.source, chosen.target))
        notes.append(f"{target} reads {source}'s {chosen.source_port} one step late (as {chosen.target_port}): "
                     "they form a loop with no feedback port, broken there")


def loop_substeps(model: AssembledModel, step_s: float) -> int:
    """Sub-steps per data step: ``ceil(step_s / MAX_LOOP_STEP_S)`` when the model closes a loop
    (a delayed connection), else 1 (a command-driven model has no loop to destabilise)."""
    delayed = component_order(model).delayed
    return max(1, int(np.ceil(step_s / MAX_LOOP_STEP_S - 1e-9))) if delayed else 1


def _effect_host(model: AssembledModel, effect: str) -> str:
    """The component spliced effect ``effect`` acts on: along its ``value_out`` (an input splice) or
    back along its ``value_in`` (an output splice), past the other effects spliced on the same port."""
    side = model.components[effect].signature.splice.side
    at = effect
    while at == effect or model.components[at].signature.kind == "effect":
        at = (next(c.target for c in model.connections if (c.source, c.source_port) == (at, "value_out"))
              if side == "input" else
              next(c.source for c in model.connections if (c.target, c.target_port) == (at, "value_in")))
    return at


class Simulator:
    """Prepared simulation of ``model`` at fixed step ``step_s`` (seconds); ``notes`` says how a
    cycle without a feedback port was broken (calibration runs report them with the data's)."""

    def __init__(self, model: AssembledModel, step_s: float, substeps: int = 1):
        if not step_s > 0:
            raise ValueError(f"step must be positive, got {step_s}")
        if int(substeps) < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps}")
        self.model = model
        self.step_s = float(step_s)
        self.substeps = int(substeps)
        self.order, self.delayed, self.notes = component_order(model)
        self.instances = {iri: model.components[iri].model_class() for iri in self.order}
        self.column = {ref.key: j for j, ref in enumerate(model.estimated_parameters)}
        self.n_parameters = len(model.estimated_parameters)
        feeding: dict[str, list[Connection]] = defaultdict(list)
        for c in model.connections:
            feeding[c.target].append(c)
        self.feeding = feeding
        boundary = set(model.boundary_inputs)
        self.unconnected: dict[str, list[str]] = {}
        for iri in self.order:
            cls = model.components[iri].model_class
            fed = {c.target_port for c in feeding[iri]}
            missing = [p.name for p in cls.inputs if p.name not in fed and p.fallback_parameter is None]
            if iri in boundary:
                missing = [m for m in missing if m != "measured_value"]
            if missing:
                self.unconnected[iri] = missing
        self.ahead, self.behind = self._memoryless_ends()
        #: Series held between data steps (schedules: a zero-order hold); others are interpolated.
        self.held = {iri for iri in model.boundary_inputs if model.components[iri].signature.steps}
        #: Effect → the host whose parameters it reads (``host_parameters``).
        self.hosts = {iri: _effect_host(model, iri) for iri in self.order
                      if model.components[iri].model_class.host_parameters}

    def _memoryless_ends(self) -> tuple[list[str], list[str]]:
        """(ahead, behind): the memoryless components evaluated over all internal steps before the
        stepping, and over the data steps after it (``docs/assembly.md``, *Stepping*), in order."""
        consumers: dict[str, set[str]] = defaultdict(set)
        for c in self.model.connections:
            consumers[c.source].add(c.target)
        in_loop = {c.source for c in self.delayed} | {c.target for c in self.delayed}
        free = {iri for iri in self.order
                if self.model.components[iri].model_class.memoryless() and iri not in in_loop}
        ahead: list[str] = []
        for iri in self.order:
            if iri in free and all(c.source in ahead for c in self.feeding[iri]):
                ahead.append(iri)
        behind: set[str] = set()
        for iri in reversed(self.order):
            if iri in free and iri not in ahead and consumers[iri] <= behind:
                behind.add(iri)
        return ahead, [iri for iri in self.order if iri in behind]

    def _parameters(self, theta: np.ndarray, fixed: Mapping[str, float]) -> dict[str, dict[str, np.ndarray]]:
        n_ens = theta.shape[0]
        params: dict[str, dict[str, np.ndarray]] = {iri: {} for iri in self.order}
        for ref in self.model.mapped_parameters:
            params[ref.component][ref.name] = np.full(n_ens, float(fixed.get(ref.key, ref.value)))
        for ref in self.model.estimated_parameters:
            if ref.key in fixed:
                params[ref.component][ref.name] = np.full(n_ens, float(fixed[ref.key]))
            else:
                params[ref.component][ref.name] = np.ascontiguousarray(theta[:, self.column[ref.key]])
        for iri, host in self.hosts.items():
            params[iri].update(self._host_values(iri, params[host]))
        return params

    def _host_values(self, iri: str, host_values: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The values in ``host_values`` of the host parameters effect ``iri`` reads (those its host has)."""
        return {name: host_values[name] for name in self.model.components[iri].model_class.host_parameters
                if name in host_values}

    def _scheduled(self, params: dict[str, dict[str, np.ndarray]], factors: Mapping[str, np.ndarray],
                   n_steps: int, n_internal: int) -> dict[str, dict[str, np.ndarray]]:
        """Component → parameter name → its value at every internal step, ``ndarray[n_internal,
        n_ensemble]``: the constant value in ``params`` times its factor per data step, held over the
        sub-steps."""
        refs = {ref.key: ref for ref in (*self.model.mapped_parameters, *self.model.estimated_parameters)}
        scheduled: dict[str, dict[str, np.ndarray]] = defaultdict(dict)
        for key, factor in factors.items():
            if key not in refs:
                raise ValueError(f"a factor for {key}, which is no parameter of the model")
            ref, factor = refs[key], np.asarray(factor, dtype=float)
            value = params[ref.component][ref.name]
            if factor.shape != (value.size, n_steps):
                raise ValueError(f"the factor for {key} has shape {factor.shape}, expected {(value.size, n_steps)}")
            scheduled[ref.component][ref.name] = np.repeat(factor.T, self.substeps, axis=0)[:n_internal] * value
        for iri, host in self.hosts.items():
            if tied := self._host_values(iri, scheduled.get(host, {})):
                scheduled[iri].update(tied)
        return scheduled

    def run(
        self,
        boundary: Mapping[str, np.ndarray],
        theta: np.ndarray,
        *,
        fixed: Mapping[str, float] | None = None,
        record: Iterable[tuple[str, str]] | None = None,
        warmup_steps: int = 0,
        factors: Mapping[str, np.ndarray] | None = None,
    ) -> SimulationResult:
        """Simulate every ensemble member over the boundary series.

        :param boundary: component IRI of a measuring device → ``ndarray[n_steps]`` measured series
            (every boundary input; targets' series are optional and only serve delayed inputs at
            step 0).
        :param theta: ``ndarray[n_ensemble, n_estimated]`` in the order of
            ``model.estimated_parameters``.
        :param fixed: parameter key → value overriding θ or a mapped value.
        :param record: the (component, port) outputs to keep; all when None.
        :param warmup_steps: the first ``warmup_steps`` data steps of ``boundary`` are a warm-up
            (:func:`warmup_index`): simulated, left out of the result (``n_steps − warmup_steps``
            steps).
        :param factors: parameter key → ``ndarray[n_ensemble, n_steps]``, a factor on that
            parameter's value (θ's, fixed or mapped) at each data step of ``boundary``, held over its
            sub-steps: a parameter that changes over time. Components read it at every step; what a
            component computes from its parameters once, in ``initial_state``, stays as it was at
            the first step.
        :raises ValueError: a boundary input without a series, series of different lengths, θ of
            the wrong shape, a warm-up as long as the series, a factor of the wrong shape or for no
            parameter of the model.
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        if theta.shape[1] != self.n_parameters:
            raise ValueError(f"theta has {theta.shape[1]} columns, the model estimates {self.n_parameters} parameters")
        missing = [iri for iri in self.model.boundary_inputs if iri not in boundary]
        if missing:
            raise ValueError(f"no measured series for boundary input(s): {', '.join(missing)}")
        lengths = {np.asarray(boundary[iri]).shape[0] for iri in boundary}
        if len(lengths) != 1:
            raise ValueError(f"boundary series have different lengths: {sorted(lengths)}")
        n_steps = lengths.pop()
        if not 0 <= warmup_steps < n_steps:
            raise InputError(f"a warm-up of {warmup_steps} steps leaves nothing of {n_steps} steps to simulate")
        n_kept = n_steps - warmup_steps
        n_ens = theta.shape[0]
        params = self._parameters(theta, fixed or {})
        substeps = self.substeps
        dt = self.step_s / substeps
        n_internal = (n_steps - 1) * substeps + 1
        scheduled = self._scheduled(params, factors, n_steps, n_internal) if factors else {}

        series: dict[str, np.ndarray] = {}
        for iri, values in boundary.items():
            filled = np.asarray(values, dtype=float).copy()
            bad = ~np.isfinite(filled)
            if bad.all():
                if iri in self.model.boundary_inputs:
                    raise InputError(f"boundary input {iri} has no finite value in the window")
                continue
            if bad.any():
                filled = held_over_gaps(filled)
            if substeps > 1 and iri in self.held:
                filled = np.repeat(filled, substeps)[:n_internal]
            elif substeps > 1:
                filled = np.interp(np.arange(n_internal) / substeps, np.arange(n_steps), filled)
            series[iri] = np.broadcast_to(filled[:, None], (filled.size, n_ens))

        wanted = None if record is None else set(record)
        components = self.model.components
        kept = {iri: [p for p in components[iri].model_class.output_names() if wanted is None or (iri, p) in wanted]
                for iri in self.order}
        ahead, behind = set(self.ahead), set(self.behind)
        stepped = [iri for iri in self.order if iri not in ahead and iri not in behind]
        links = {iri: [(c.target_port, (c.source, c.source_port), c in self.delayed) for c in self.feeding[iri]]
                 for iri in self.order}

        def evaluate_at_once(iri: str, sources: Mapping, measured: np.ndarray | None, shape: tuple[int, int]):
            p = params[iri]
            if iri in scheduled:  # a parameter that changes: its value at every internal step, or at the kept data steps
                at_data_steps = shape[0] != n_internal
                p = p | {name: values[::substeps][warmup_steps:] if at_data_steps else values
                         for name, values in scheduled[iri].items()}
            inputs = {name: np.full(n_ens, np.nan) for name in self.unconnected.get(iri, [])}
            inputs.update({name: sources[source] for name, source, _ in links[iri]})
            if measured is not None:
                inputs["measured_value"] = measured
            outputs = self.instances[iri].step(p, inputs, {}, dt)
            return {(iri, port): np.broadcast_to(value, shape) for port, value in outputs.items()}

        # memoryless components fed by the boundary alone: every internal step in one call
        early: dict[tuple[str, str], np.ndarray] = {}
        for iri in self.ahead:
            measured = series.get(iri) if iri in self.model.boundary_inputs else None
            early.update(evaluate_at_once(iri, early, measured, (n_internal, n_ens)))

        # the rest, step by step (a loop's state or a delayed input); what they need of `early`
        # is one row per step, and what `behind` needs of them is recorded at the data steps
        needed_late = {src for iri in self.behind for _, src, _ in links[iri] if src[0] not in ahead}
        feeding_steps = [(src, early[src]) for src in sorted({src for iri in stepped for _, src, _ in links[iri]
                                                              if src[0] in ahead})]
        buffers: dict[tuple[str, str], np.ndarray] = {}
        plan = []
        for iri in stepped:
            record_ports = sorted(set(kept[iri]) | {port for source, port in needed_late if source == iri})
            for port in record_ports:
                buffers[(iri, port)] = np.empty((n_kept, n_ens))
            # the parameter and input dicts are made once and refilled at every step
            plan.append((iri, self.instances[iri], dict(params[iri]),
                         {name: np.full(n_ens, np.nan) for name in self.unconnected.get(iri, [])},
                         [(name, source) for name, source, late in links[iri] if not late],
                         [(name, source) for name, source, late in links[iri] if late],
                         series.get(iri) if iri in self.model.boundary_inputs else None,
                         [(port, buffers[(iri, port)]) for port in record_ports],
                         list(scheduled.get(iri, {}).items())))

        current: dict[tuple[str, str], np.ndarray] = {}
        previous: dict[tuple[str, str], np.ndarray] = {}
        for (iri, _port) in {src for entry in plan for _, src in entry[5]}:
            start = series.get(iri)
            previous[(iri, _port)] = start[0].copy() if start is not None else np.zeros(n_ens)
        states: dict[str, dict] = {}

        def advance(i: int, record: bool) -> None:
            """Step every stepped component from internal step ``i`` (initialising it at 0)."""
            k, offset = divmod(i, substeps)
            for key, values in feeding_steps:
                current[key] = values[i]
            for iri, instance, p, inputs, live, late, measured, keep, varying in plan:
                for name, values in varying:
                    p[name] = values[i]
                for name, source in live:
                    inputs[name] = current[source]
                for name, source in late:
                    inputs[name] = previous[source]
                if measured is not None:
                    inputs["measured_value"] = measured[i]
                if i == 0:
                    states[iri] = instance.initial_state(p, inputs, dt)
                outputs = instance.step(p, inputs, states[iri], dt)
                for port, value in outputs.items():
                    current[(iri, port)] = value
                if record and offset == 0 and k >= warmup_steps:
                    for port, buffer in keep:
                        buffer[k - warmup_steps] = outputs[port]

        # a delayed input off a feedback port and without a measured seed starts from its source's
        # output of a first pass over step 0 (docs/assembly.md, *Order and feedback*)
        unseeded = {(c.source, c.source_port) for c in self.delayed if series.get(c.source) is None
                    and not components[c.target].model_class.port(c.target_port).feedback}
        if plan and unseeded:
            advance(0, record=False)
            for key in unseeded:
                previous[key] = current[key]
            states.clear()  # free the first pass's states (an FMU's instances) before step 0 makes new ones
        for i in range(n_internal if plan else 0):
            advance(i, record=True)
            for key in previous:
                previous[key] = current[key]

        # memoryless components that only feed each other: at the data steps, in one call each
        at_data_steps = {key: values[::substeps][warmup_steps:] for key, values in early.items()} | buffers
        for iri in self.behind:
            at_data_steps.update(evaluate_at_once(iri, at_data_steps, None, (n_kept, n_ens)))
        outputs = {(iri, port): at_data_steps[(iri, port)] for iri in self.order for port in kept[iri]}
        return SimulationResult({key: values.T if key in buffers else np.array(values.T)
                                 for key, values in outputs.items()}, self.step_s)


def simulate(
    model: AssembledModel, boundary: Mapping[str, np.ndarray], theta: np.ndarray, *, step_s: float,
    fixed: Mapping[str, float] | None = None, substeps: int = 1,
) -> SimulationResult:
    """One-shot :class:`Simulator` run (prepare + run)."""
    return Simulator(model, step_s, substeps).run(boundary, theta, fixed=fixed)


def target_series(model: AssembledModel, result: SimulationResult, member: int = 0) -> dict[str, np.ndarray]:
    """Building node IRI of every target (virtual sensor) → its simulated ``ndarray[n_steps]`` for
    ensemble member ``member``, in the port unit: what
    :func:`service.data.measurements.write_comparison_csv` writes beside the measurements."""
    return {model.measurement(c).node: result.target(c)[member] for c in model.targets}
