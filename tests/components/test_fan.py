"""Fan: part-load power curve, mass flow, clipping (hand-computed values)."""

import numpy as np
import pytest

from service.components.fan import Fan

# ASHRAE 90.1 Appendix G defaults: c1..c4 = 0.0013, 0.1470, 0.9506, −0.0998; P_nom 1800 W, V̇_nom 1.5 m³/s.


def _fan(run_model, params, flow, inlet=4.0):
    inputs = {"air_volume_flow": np.array([flow]), "inlet_air_temperature": np.array([inlet])}
    return {k: v[0] for k, v in run_model(Fan, params, inputs)[0].items()}


def test_nominal_flow_draws_nominal_power_times_the_curve_sum(run_model, params_for):
    out = _fan(run_model, params_for(Fan), 1.5)
    assert out["electric_power"] == pytest.approx(1800.0 * 0.9991, rel=1e-12)  # 1798.38 W
    assert out["outlet_air_mass_flow"] == pytest.approx(1.204 * 1.5, rel=1e-12)
    assert out["outlet_air_temperature"] == 4.0


def test_half_flow_follows_the_cubic(run_model, params_for):
    # f = 0.5: 0.0013 + 0.1470·0.5 + 0.9506·0.25 − 0.0998·0.125 = 0.299975
    assert _fan(run_model, params_for(Fan), 0.75)["electric_power"] == pytest.approx(1800.0 * 0.299975, rel=1e-12)


def test_no_or_reversed_flow_is_a_fan_that_is_off_it_draws_nothing_and_moves_no_air(run_model, params_for):
    for flow in (0.0, -0.3):
        out = _fan(run_model, params_for(Fan), flow)
        assert out["electric_power"] == 0.0
        assert out["outlet_air_mass_flow"] == 0.0
    # running at the smallest flow, it draws the curve's constant term
    assert _fan(run_model, params_for(Fan), 1e-9)["electric_power"] == pytest.approx(1800.0 * 0.0013, rel=1e-6)


def test_a_negative_curve_value_gives_zero_power(run_model, params_for):
    params = params_for(Fan, c1=0.0, c2=-0.5, c3=0.0, c4=0.0)
    assert _fan(run_model, params, 0.75)["electric_power"] == 0.0
