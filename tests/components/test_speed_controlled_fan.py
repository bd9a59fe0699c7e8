"""Speed-controlled fan: flow from the speed command, the Fan's power curve, clipping."""

import numpy as np
import pytest

from service.components.fan import Fan
from service.components.speed_controlled_fan import SpeedControlledFan


def _fan(run_model, params, speed, inlet=16.0):
    inputs = {"speed": np.atleast_1d(speed).astype(float), "inlet_air_temperature": np.full(np.size(speed), inlet)}
    return run_model(SpeedControlledFan, params, inputs)[0]


def test_half_speed_moves_half_the_nominal_flow_at_the_curve_power(run_model, params_for):
    out = _fan(run_model, params_for(SpeedControlledFan), 0.5)
    assert out["outlet_air_mass_flow"][0] == pytest.approx(1.204 * 0.75, rel=1e-12)
    assert out["electric_power"][0] == pytest.approx(1800.0 * 0.299975, rel=1e-12)  # see test_fan
    # the impeller's 0.3 of 539.96 W into 0.903 kg/s of air: +0.1783 K
    assert out["outlet_air_temperature"][0] == pytest.approx(16.0 + 0.3 * 1800.0 * 0.299975 / (1.204 * 0.75 * 1006.0),
                                                             rel=1e-12)


def test_commands_outside_zero_to_one_are_clipped_and_a_fan_at_speed_zero_is_off(run_model, params_for):
    out = _fan(run_model, params_for(SpeedControlledFan, n=2), np.array([1.2, -0.04]))
    np.testing.assert_allclose(out["outlet_air_mass_flow"], [1.204 * 1.5, 0.0], rtol=1e-12)
    np.testing.assert_allclose(out["electric_power"], [1800.0 * 0.9991, 0.0], rtol=1e-12)


def test_equals_the_fan_at_the_flow_its_speed_gives(run_model):
    rng = np.random.default_rng(1)
    n = 50
    params = {p.name: p.lower + rng.random(n) * (p.upper - p.lower) for p in Fan.parameters}
    speed = rng.random(n)
    by_speed = run_model(SpeedControlledFan, params, {"speed": speed, "inlet_air_temperature": np.full(n, 9.0)})[0]
    by_flow = run_model(Fan, params, {"air_volume_flow": speed * params["nominal_air_flow"],
                                      "inlet_air_temperature": np.full(n, 9.0)})[0]
    for port in Fan.output_names():
        np.testing.assert_allclose(by_speed[port], by_flow[port], rtol=1e-12, err_msg=port)
