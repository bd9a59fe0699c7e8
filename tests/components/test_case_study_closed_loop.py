"""The whole case study for one day at 1-minute steps: the controller tracks a setpoint step."""

import numpy as np

from service.model.assembly import assemble
from service.model.simulator import Simulator, loop_substeps


def test_the_controller_tracks_a_setpoint_step(case_store):
    model = assemble(case_store, "case")
    n = 1440
    step_s = 60.0
    series = {"supply_air_flow": np.full(n, 1.2), "fan_inlet_air_temperature": np.full(n, 2.0),
              "supply_water_temperature": np.full(n, 65.0),
              "coil_outlet_air_temperature_setpoint": np.where(np.arange(n) < 600, 16.0, 19.0)}
    boundary = {c: series[model.measurement(c).series_id] for c in model.boundary_inputs}
    theta = np.array([[r.spec.default for r in model.estimated_parameters]])
    sensor = next(c for c in model.targets if model.measurement(c).node.endswith("coil_outlet_air_temperature_sensor"))
    result = Simulator(model, step_s, loop_substeps(model, step_s)).run(boundary, theta)
    outlet = result.target(sensor)[0]
    assert abs(outlet[540:600].mean() - 16.0) < 0.1  # settled before the step
    assert abs(outlet[-60:].mean() - 19.0) < 0.1  # and after it
    assert outlet[600] < 18.5  # the step is not instantaneous
