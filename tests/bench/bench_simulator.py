"""Simulator throughput: the case study over one week of 10-minute data, vectorised over the ensemble,
against a plain Python loop over members and time steps (the baseline, measured in the same run).

The figure is member-evaluations performed per second: each component model's ``step`` is wrapped
by a counter (:class:`CountingModel`) that adds, per call, the number of (time point, member) pairs
it evaluates — ``n_ensemble`` for a step, time points × ``n_ensemble`` for a memoryless component
evaluated over the whole series at once. A table says, per component, how the simulator evaluates
it: whole array over every internal step, stepped at every internal step, or whole array at the
data steps only. The baseline (:func:`member_loop`) is the loop a user would write: for each member,
for each internal step, each component's model with arrays of length 1 in topological order, a
controller's feedback input served one step late; it is checked against the simulator's outputs,
timed on a few members and scaled per member (the fastest member; the simulator's fastest of three
runs).

Then the FMU component (``service.components.fmu``; the test FMU ``FanLag`` compiled from
``tests/fixtures/fmu_src`` when ``gcc`` exists): flow sensor → FMU fan → power meter over one day of
1-minute steps, with one FMU instance per member kept alive through the run (the module's choice)
against re-running the model member by member (what reset-and-re-run costs: the fresh instance of
each run costs what ``fmi2Reset`` + initialisation would).

    python tests/bench/bench_simulator.py
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Mapping, Sequence
from graphlib import TopologicalSorter
from pathlib import Path

import numpy as np

from service.components.component import ComponentModel
from service.data.synthetic_operation import case_study_operation
from service.graph.store import GraphStore
from service.model.assembled_model import AssembledModel
from service.model.assembly import assemble
from service.model.simulator import Simulator, loop_substeps
from service.resources import examples_dir

#: Members the baseline loop runs (each timed, and compared with the simulator's outputs).
LOOP_MEMBERS = 3
#: Timed runs of the simulator per ensemble size; the fastest counts, as the fastest member of the loop does.
REPEATS = 3


def timed(run) -> float:
    """Wall time of ``run()``, s."""
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


class CountingModel:
    """A component model whose ``step`` counts the calls and the member-evaluations it performs: per
    call, the size of its parameters and inputs broadcast together."""

    def __init__(self, model: ComponentModel):
        self.model = model
        self.calls = 0
        self.evaluations = 0

    def initial_state(self, params, inputs, dt_s):
        return self.model.initial_state(params, inputs, dt_s)

    def step(self, params, inputs, state, dt_s):
        self.calls += 1
        shape = np.broadcast_shapes(*(np.shape(v) for v in (*params.values(), *inputs.values())))
        self.evaluations += int(np.prod(shape))
        return self.model.step(params, inputs, state, dt_s)


def evaluation_kind(simulator: Simulator, iri: str) -> str:
    """How ``simulator`` evaluates component ``iri`` (``docs/assembly.md``, *Stepping*)."""
    if iri in simulator.ahead:
        return "static: whole array, every internal step"
    if iri in simulator.behind:
        return "static: whole array, data steps only"
    return "stepped: every internal step"


def member_loop(model: AssembledModel, boundary: Mapping[str, np.ndarray], theta: np.ndarray, step_s: float,
                substeps: int, record: Sequence[tuple[str, str]]) -> dict[tuple[str, str], np.ndarray]:
    """One member θ ``ndarray[n_estimated]`` simulated as a user would loop it: the boundary series
    at ``step_s / substeps`` (schedules held, the others interpolated), every component's model
    called at every internal step with arrays of length 1, in topological order of the connections
    that do not feed a ``feedback`` port; those serve their source's output of the step before (at
    step 0 its measured value, else 0). Returns ``record``'s outputs at the data steps."""
    feeds = defaultdict(list)
    for c in model.connections:
        feeds[c.target].append(c)
    late = {c for c in model.connections if model.components[c.target].model_class.port(c.target_port).feedback}
    order = list(TopologicalSorter({iri: {c.source for c in feeds[iri] if c not in late}
                                    for iri in model.components}).static_order())
    models = {iri: model.components[iri].model_class() for iri in order}
    params = {iri: {} for iri in order}
    for ref in model.mapped_parameters:
        params[ref.component][ref.name] = np.array([ref.value])
    for ref, value in zip(model.estimated_parameters, theta):
        params[ref.component][ref.name] = np.array([value])

    n_steps = len(next(iter(boundary.values())))
    n_internal = (n_steps - 1) * substeps + 1
    dt_s = step_s / substeps
    measured = {iri: np.repeat(boundary[iri], substeps)[:n_internal] if model.components[iri].signature.steps
                else np.interp(np.arange(n_internal) / substeps, np.arange(n_steps), boundary[iri])
                for iri in model.boundary_inputs}
    previous = {(c.source, c.source_port): np.array([boundary[c.source][0] if c.source in boundary else 0.0])
                for c in late}
    outputs: dict[tuple[str, str], np.ndarray] = {}
    states = {}
    kept = {key: np.empty(n_steps) for key in record}
    for i in range(n_internal):
        for iri in order:
            inputs = {}
            for c in feeds[iri]:
                source = (c.source, c.source_port)
                inputs[c.target_port] = previous[source] if c in late else outputs[source]
            if iri in measured:
                inputs["measured_value"] = measured[iri][i:i + 1]
            if i == 0:
                states[iri] = models[iri].initial_state(params[iri], inputs, dt_s)
            for port, value in models[iri].step(params[iri], inputs, states[iri], dt_s).items():
                outputs[(iri, port)] = value
        for key in previous:
            previous[key] = outputs[key]
        if i % substeps == 0:
            for key in kept:
                kept[key][i // substeps] = outputs[key][0]
    return kept


def main() -> None:
    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    model = assemble(store, "case")
    operation = case_study_operation(n_days=7, step_s=600.0, seed=0)
    boundary = {c: operation.series[model.measurement(c).series_id] for c in model.boundary_inputs}
    substeps = loop_substeps(model, 600.0)
    simulator = Simulator(model, 600.0, substeps)
    counted = Simulator(model, 600.0, substeps)
    counters = {iri: CountingModel(instance) for iri, instance in counted.instances.items()}
    counted.instances.update(counters)
    rng = np.random.default_rng(0)
    lower = np.array([r.spec.lower for r in model.estimated_parameters])
    upper = np.array([r.spec.upper for r in model.estimated_parameters])
    record = [(c, "measured_value") for c in model.targets]
    n_steps = len(operation.timestamps)
    n_internal = (n_steps - 1) * substeps + 1
    print(f"case study: {len(model.components)} components, {n_steps} data steps, {n_internal} internal steps "
          f"(1 week, 10-min data, {substeps} sub-steps)")

    counted.run(boundary, lower[None, :], record=record)
    print(f"\n{'component':40s} {'model':16s} {'evaluated':42s} {'calls':>6s} {'member-evaluations':>18s}")
    for iri in simulator.order:
        counter = counters[iri]
        print(f"{iri.rsplit('/', 1)[-1]:40s} {type(counter.model).__name__:16s} {evaluation_kind(simulator, iri):42s} "
              f"{counter.calls:6d} {counter.evaluations:18,d}")
    per_member = sum(c.evaluations for c in counters.values())
    every_step = len(model.components) * n_internal
    print(f"{'all, per member':108s} {per_member:18,d}\n(every component at every internal step would be "
          f"{every_step:,d}: {every_step / per_member:.2f}x what is performed)")

    theta = lower + rng.random((LOOP_MEMBERS, lower.size)) * (upper - lower)
    result = simulator.run(boundary, theta, record=record)
    member_s = []
    for m, member in enumerate(theta):
        start = time.perf_counter()
        outputs = member_loop(model, boundary, member, 600.0, substeps, record)
        member_s.append(time.perf_counter() - start)
        for key, values in outputs.items():
            np.testing.assert_allclose(values, result.outputs[key][m], rtol=1e-9, atol=1e-9, err_msg=key[0])
    loop_per_member = min(member_s)
    loop_evaluations = len(model.components) * n_internal
    print(f"\nbaseline: a Python loop over members and internal steps, outputs equal to the simulator's; "
          f"{loop_per_member:.3f} s per member (fastest of {LOOP_MEMBERS}), "
          f"{loop_evaluations / loop_per_member / 1e6:.3f} M member-evaluations/s "
          f"(every component at every internal step)")

    for n_ensemble in (1, 64, 256, 1024):
        theta = lower + rng.random((n_ensemble, lower.size)) * (upper - lower)
        for counter in counters.values():
            counter.evaluations = 0
        counted.run(boundary, theta, record=record)
        performed = sum(c.evaluations for c in counters.values())
        vectorised = min(timed(lambda: simulator.run(boundary, theta, record=record)) for _ in range(REPEATS))
        loop = loop_per_member * n_ensemble
        print(f"ensemble {n_ensemble:5d}: {vectorised:7.3f} s, {performed / vectorised / 1e6:7.2f} M "
              f"member-evaluations/s performed; the loop {loop:8.2f} s: {loop / vectorised:7.1f}x")


def fmu_section() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from fan_lag_fmu import build_fan_lag_fmu, fan_lag_model

    with tempfile.TemporaryDirectory() as folder:
        try:
            fmu = build_fan_lag_fmu(Path(folder))
        except FileNotFoundError as exc:
            print(f"FMU component: skipped ({exc})")
            return
        model = fan_lag_model(fmu)
        simulator = Simulator(model, 60.0)
        flow = 1.5 * (0.5 + 0.4 * np.sin(np.arange(1440) * 2 * np.pi / 1440))
        boundary = {"urn:flow": flow}
        print(f"\nFMU fan (flow sensor → FMU → meter), {flow.size} steps (1 day, 1-min):")
        rng = np.random.default_rng(1)
        for n_ensemble in (1, 64, 256):
            theta = np.column_stack([rng.uniform(500, 5000, n_ensemble), rng.uniform(10, 300, n_ensemble)])
            start = time.perf_counter()
            simulator.run(boundary, theta)
            kept_alive = time.perf_counter() - start
            line = (f"ensemble {n_ensemble:5d}: instances kept alive {kept_alive:6.3f} s "
                    f"({kept_alive / (n_ensemble * flow.size) * 1e6:5.2f} µs per member-step)")
            if n_ensemble == 64:
                start = time.perf_counter()
                for member in theta:
                    simulator.run(boundary, member[None, :])
                rerun = time.perf_counter() - start
                line += f"; member by member {rerun:6.3f} s ({rerun / kept_alive:.1f}x slower)"
            print(line)


if __name__ == "__main__":
    main()
    fmu_section()
