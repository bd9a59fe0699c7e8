"""Wall time of ``diagnose`` on one week of 10-minute case-study data with the full effect catalog
(goal: under 10 s on the 2-core development machine, issue 31), against the base point calibration
alone (the baseline, measured in the same run).

    python tests/bench/bench_diagnose.py [--hidden-effect FanMotorHeat]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from service.calibration.run import calibrate  # noqa: E402
from service.components.library import SignatureLibrary  # noqa: E402
from service.data.synthetic import generate_synthetic_data  # noqa: E402
from service.diagnosis.loop import diagnose  # noqa: E402
from service.graph.store import GraphStore  # noqa: E402
from service.resources import examples_dir  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--hidden-effect", default="FanMotorHeat")
    args = parser.parse_args()
    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    with tempfile.TemporaryDirectory() as folder:
        data = Path(folder) / "week.csv"
        generate_synthetic_data(store, "case", data, library=SignatureLibrary.load(),
                                hidden_effect=args.hidden_effect, seed=1)
        train, test = ("2026-01-12", "2026-01-15T23:59"), ("2026-01-16", None)
        start = time.perf_counter()
        calibrate(store, "case", data, train=train, test=test, seed=0)
        base = time.perf_counter() - start
        start = time.perf_counter()
        report = diagnose(store, "case", data, train=train, test=test, seed=0)
        total = time.perf_counter() - start
    print(f"base point calibration: {base:6.1f} s")
    print(f"diagnose ({len(report.effects)} candidates): {total:6.1f} s = {total / base:.1f}x the base calibration; "
          f"goal < 10 s: {'met' if total < 10 else 'NOT met'}")
    print(f"top candidate: {report.effects[0].effect} at {report.effects[0].node}")


if __name__ == "__main__":
    main()
