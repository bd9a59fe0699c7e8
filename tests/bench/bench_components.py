"""Component throughput: member-steps per second of every library model at ensemble 256, against the
same model stepped with one member (the per-member loop's cost per member, measured in this run).
The simulator's own figure, member-evaluations performed per second: ``tests/bench/bench_simulator.py``.

    python tests/bench/bench_components.py
"""

from __future__ import annotations

import time

import numpy as np

from service.components.library import SignatureLibrary, load_model_class

_BY_NAME = {"supply_water_temperature": 65.0, "outdoor_air_temperature": 5.0, "return_air_temperature": 22.0,
            "inlet_air_temperature": 12.0, "setpoint": 21.0, "ambient_temperature": 15.0}
_BY_UNIT = {"degC": 18.0, "kg/s": 1.5, "m3/s": 1.2, "1": 0.4, "W": 1500.0, "": 19.0}
STEPS = 1440  # one simulated day at one-minute steps


def _seconds_per_step(cls, n: int) -> float:
    rng = np.random.default_rng(0)
    params = {p.name: p.lower + rng.random(n) * (p.upper - p.lower) for p in cls.parameters}
    inputs = {p.name: np.full(n, _BY_NAME.get(p.name, _BY_UNIT[p.unit])) for p in cls.inputs}
    model = cls()
    state = model.initial_state(params, inputs, 60.0)
    model.step(params, inputs, state, 60.0)  # a compiled step is compiled, or loaded from its cache, untimed
    start = time.perf_counter()
    for _ in range(STEPS):
        model.step(params, inputs, state, 60.0)
    return (time.perf_counter() - start) / STEPS


def main() -> None:
    classes = sorted({load_model_class(s) for s in SignatureLibrary.load().values() if s.model},
                     key=lambda c: c.__name__)
    print(f"{STEPS} steps per model; rate = member-steps/s")
    print(f"{'model':22s} {'n=1 µs/step':>12s} {'n=256 µs/step':>14s} {'M steps/s':>10s} {'× per-member loop':>18s}")
    for cls in classes:
        single = _seconds_per_step(cls, 1)
        ensemble = _seconds_per_step(cls, 256)
        print(f"{cls.__name__:22s} {single * 1e6:12.1f} {ensemble * 1e6:14.1f} {256 / ensemble / 1e6:10.1f} "
              f"{256 * single / ensemble:18.1f}")


if __name__ == "__main__":
    main()
