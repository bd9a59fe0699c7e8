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
    # the impeller's losses, 0.3 of the power, into 1.806 kg/s of air: 0.3·1798.38/(1.806·1006) = 0.2970 K
    assert out["outlet_air_temperature"] == pytest.approx(4.0 + 0.3 * 1798.38 / (1.204 * 1.5 * 1006.0), rel=1e-5)


def test_a_fan_that_is_off_or_whose_impeller_heat_is_not_counted_leaves_the_air_at_its_inlet_temperature(
        run_model, params_for):
    assert _fan(run_model, params_for(Fan), 0.0)["outlet_air_temperature"] == 4.0
    assert _fan(run_model, params_for(Fan, impeller_heat_share=0.0), 1.5)["outlet_air_temperature"] == 4.0


def test_the_impeller_heat_is_counted_only_where_a_meter_measures_the_power():
    """Where no meter measures the power, its curve is fixed at the defaults too: fitted, it made the
    motor's heat in the air stream (f_m·P) a heat source of any cubic shape of the flow."""
    from service.components.speed_controlled_fan import SpeedControlledFan

    assert Fan.parameters_fixed_by_measurement(frozenset({"electric_power"})) == {"impeller_heat_share": 0.3}
    curve = {"nominal_power": 1800.0, "c1": 0.0013, "c2": 0.1470, "c3": 0.9506, "c4": -0.0998}
    assert Fan.parameters_fixed_by_measurement(frozenset({"outlet_air_temperature"})) == {
        "impeller_heat_share": 0.0, "nominal_air_flow": 1.5, **curve}
    # a speed-controlled fan's nominal flow sets the air flow the targets see: estimated still
    assert SpeedControlledFan.parameters_fixed_by_measurement(frozenset()) == {"impeller_heat_share": 0.0, **curve}


def test_motor_heat_adds_its_share_on_top_of_the_impellers(run_model, params_for):
    from service.components.effects.fan_motor_heat import FanMotorHeat

    fan = _fan(run_model, params_for(Fan), 1.5)
    inputs = {"value_in": np.array([fan["outlet_air_temperature"]]),
              "electric_power": np.array([fan["electric_power"]]),
              "air_mass_flow": np.array([fan["outlet_air_mass_flow"]])}
    out = run_model(FanMotorHeat, params_for(FanMotorHeat, motor_heat_fraction=0.6), inputs)[0]["value_out"][0]
    # 0.3 + 0.6 of 1798.38 W into 1.806 kg/s: 0.9·1798.38/(1.806·1006) = 0.8909 K
    assert out - 4.0 == pytest.approx(0.9 * 1798.38 / (1.806 * 1006.0), rel=1e-5)


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
