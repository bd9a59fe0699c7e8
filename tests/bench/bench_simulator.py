"""Simulator throughput: the case study over one week of 10-minute data, vectorised over the ensemble,
against a plain per-member loop over the same components (the baseline, measured in the same run).

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
from pathlib import Path

import numpy as np

from service.data.synthetic_operation import case_study_operation
from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.model.simulator import Simulator, loop_substeps
from service.resources import examples_dir


def main() -> None:
    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    model = assemble(store, "case")
    operation = case_study_operation(n_days=7, step_s=600.0, seed=0)
    boundary = {c: operation.series[model.measurement(c).series_id] for c in model.boundary_inputs}
    substeps = loop_substeps(model, 600.0)
    simulator = Simulator(model, 600.0, substeps)
    rng = np.random.default_rng(0)
    lower = np.array([r.spec.lower for r in model.estimated_parameters])
    upper = np.array([r.spec.upper for r in model.estimated_parameters])
    n_internal = (len(operation.timestamps) - 1) * substeps + 1
    n_components = len(model.components)
    record = [(c, "measured_value") for c in model.targets]
    print(f"case study: {n_components} components, {n_internal} internal steps (1 week, 10-min data, "
          f"{substeps} sub-steps)")
    baseline = None
    for n_ensemble in (1, 64, 256, 1024):
        theta = lower + rng.random((n_ensemble, lower.size)) * (upper - lower)
        start = time.perf_counter()
        simulator.run(boundary, theta, record=record)
        vectorised = time.perf_counter() - start
        if baseline is None:
            baseline = vectorised  # one member: the per-member loop's cost per member
        per_member_loop = baseline * n_ensemble
        rate = n_ensemble * n_internal * n_components / vectorised
        print(f"ensemble {n_ensemble:5d}: {vectorised:7.3f} s, {rate / 1e6:7.2f} M component-steps/s, "
              f"{per_member_loop / vectorised:7.1f}x a per-member loop ({per_member_loop:.2f} s)")


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
        print(f"FMU fan (flow sensor → FMU → meter), {flow.size} steps (1 day, 1-min):")
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
