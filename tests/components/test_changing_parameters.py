"""A parameter that changes over time (a drift's factor: the simulator hands the component a new array
at every step) is read at the step it comes: components that keep something computed from their
parameters between steps (the hot-water loop's packed parameters, a lag's factor) notice the new array."""

import numpy as np
import pytest

from service.components.effects.first_order_lag import FirstOrderLag
from service.components.hot_water_loop import HotWaterLoop

DT = 120.0

CASES = [  # (model class, the parameter changed, factors on its two members, the output compared)
    (HotWaterLoop, "water_side_conductance", [0.5, 2.0], "heat_rate"),
    (HotWaterLoop, "supply_pipe_time_constant", [0.3, 3.0], "inlet_water_temperature"),
    (FirstOrderLag, "time_constant", [0.2, 5.0], "value_out"),
]


@pytest.mark.parametrize(("cls", "name", "factors", "port"), CASES, ids=[f"{c[0].__name__}-{c[1]}" for c in CASES])
def test_a_parameter_given_as_a_new_array_is_read_at_that_step(cls, name, factors, port, params_for, inputs_for):
    params = params_for(cls, n=2)
    if cls is FirstOrderLag:
        params["time_constant"] = np.full(2, 300.0)
    start = inputs_for(cls, n=2)
    moved = {key: values * 0.8 for key, values in start.items()}  # a change of the inputs the states follow
    model = cls()
    state = model.initial_state(params, start, DT)
    model.step(params, moved, state, DT)
    changed = dict(params, **{name: params[name] * np.array(factors)})
    unchanged_copy = {key: np.array(values, copy=True) for key, values in state.items() if not key.startswith("_")}
    fresh = {key: np.array(values, copy=True) for key, values in state.items() if not key.startswith("_")}
    kept = model.step(params, moved, unchanged_copy, DT)[port]
    expected = model.step(changed, moved, fresh, DT)[port]  # nothing kept from the old values
    got = model.step(changed, moved, state, DT)[port]
    assert not np.allclose(expected, kept)  # the change matters at this step
    np.testing.assert_array_equal(got, expected)
