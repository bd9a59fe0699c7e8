"""Mixing box: outdoor-air fraction 0 and 1, the damper characteristic, clipping; the effect of a
recirculated flow that does not follow the supply fan."""

import numpy as np
import pytest

from service.components.effects.return_flow_off_fan_speed import ReturnFlowOffFanSpeed
from service.components.mixing_box import MixingBox


def _mix(run_model, params, damper, outdoor=5.0, ret=22.0):
    n = np.size(damper)
    inputs = {"outdoor_air_temperature": np.full(n, outdoor), "return_air_temperature": np.full(n, ret),
              "outdoor_damper_position": np.atleast_1d(np.asarray(damper, float))}
    return run_model(MixingBox, params, inputs)[0]


def test_fraction_zero_gives_return_air_and_fraction_one_outdoor_air(run_model, params_for):
    tight = params_for(MixingBox, n=2, minimum_outdoor_air_fraction=0.0, maximum_outdoor_air_fraction=1.0)
    out = _mix(run_model, tight, [0.0, 1.0])
    np.testing.assert_array_equal(out["outdoor_air_fraction"], [0.0, 1.0])
    np.testing.assert_array_equal(out["mixed_air_temperature"], [22.0, 5.0])


def test_damper_characteristic_by_hand(run_model, params_for):
    # x = 0.05 + (0.9 − 0.05)·0.5² = 0.2625; T_mix = 22 + 0.2625·(5 − 22) = 17.5375 °C
    out = _mix(run_model, params_for(MixingBox, damper_exponent=2.0), 0.5)
    assert out["outdoor_air_fraction"][0] == pytest.approx(0.2625, rel=1e-12)
    assert out["mixed_air_temperature"][0] == pytest.approx(17.5375, rel=1e-12)


def test_commands_below_zero_or_above_one_are_clipped(run_model, params_for):
    out = _mix(run_model, params_for(MixingBox, n=2), [-0.04, 1.3])  # FLEXLAB logs −0.04
    np.testing.assert_allclose(out["outdoor_air_fraction"], [0.05, 0.9], rtol=1e-12)


def test_mixed_air_lies_between_the_two_streams(run_model):
    rng = np.random.default_rng(2)
    n = 200
    params = {p.name: p.lower + rng.random(n) * (p.upper - p.lower) for p in MixingBox.parameters}
    outdoor, ret = rng.uniform(-15, 35, n), rng.uniform(18, 28, n)
    out = run_model(MixingBox, params, {"outdoor_air_temperature": outdoor, "return_air_temperature": ret,
                                        "outdoor_damper_position": rng.uniform(-0.1, 1.1, n)})[0]
    mixed = out["mixed_air_temperature"]
    assert np.all((mixed >= np.minimum(outdoor, ret) - 1e-12) & (mixed <= np.maximum(outdoor, ret) + 1e-12))


def test_a_recirculated_flow_that_ignores_the_fan_speed_is_a_mass_balance(run_model, params_for):
    """ReturnFlowOffFanSpeed at β = 1 is the mixing of a fixed recirculated flow into a supply flow
    that scales with the fan: at full speed the damper law's fraction x, at speed s a recirculated
    share (1 − x)/s; at β = 0 the base model; below x' = 0 the mixed air is the return air."""
    x, ret, outdoor, nominal_kg_s = 0.3, 21.0, -2.0, 2.0
    speed = np.array([1.0, 0.8, 0.5, 0.2])
    supply, recirculated = speed * nominal_kg_s, (1 - x) * nominal_kg_s * np.ones(4)
    by_mass_balance = np.where(recirculated < supply, (recirculated * ret + (supply - recirculated) * outdoor) / supply, ret)
    inputs = {"value_in": np.full(4, ret + x * (outdoor - ret)), "outdoor_air_temperature": np.full(4, outdoor),
              "return_air_temperature": np.full(4, ret), "fan_speed": speed}
    fixed = run_model(ReturnFlowOffFanSpeed, params_for(ReturnFlowOffFanSpeed, n=4, recirculation_speed_exponent=1.0), inputs)[0]
    np.testing.assert_allclose(fixed["value_out"], by_mass_balance, rtol=1e-12)
    assert by_mass_balance[-1] == ret  # at 20 % speed the fixed recirculated flow exceeds the supply: no outdoor air
    null = run_model(ReturnFlowOffFanSpeed, params_for(ReturnFlowOffFanSpeed, n=4, which="null"), inputs)[0]
    np.testing.assert_array_equal(null["value_out"], inputs["value_in"])
