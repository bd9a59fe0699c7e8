"""Simulator throughput: the case study over one week of 10-minute data, vectorised over the ensemble,
against a plain per-member loop over the same components (the baseline, measured in the same run).

    python tests/bench/bench_simulator.py
"""

from __future__ import annotations

import time

import numpy as np

from service.assembly import assemble
from service.calibration_run import DEFAULT_SUBSTEPS
from service.resources import examples_dir
from service.simulator import Simulator
from service.store import GraphStore
from service.synthetic_operation import case_study_operation


def main() -> None:
    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    model = assemble(store, "case")
    operation = case_study_operation(n_days=7, step_s=600.0, seed=0)
    boundary = {c: operation.series[model.measurement(c).series_id] for c in model.boundary_inputs}
    simulator = Simulator(model, 600.0, DEFAULT_SUBSTEPS)
    rng = np.random.default_rng(0)
    lower = np.array([r.spec.lower for r in model.estimated_parameters])
    upper = np.array([r.spec.upper for r in model.estimated_parameters])
    n_internal = (len(operation.timestamps) - 1) * DEFAULT_SUBSTEPS + 1
    n_components = len(model.components)
    record = [(c, "measured_value") for c in model.targets]
    print(f"case study: {n_components} components, {n_internal} internal steps (1 week, 10-min data, "
          f"{DEFAULT_SUBSTEPS} sub-steps)")
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


if __name__ == "__main__":
    main()
