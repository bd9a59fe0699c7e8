"""Component models: hand-computed values, limits, energy balance, the contract every model keeps."""

import numpy as np
import pytest

from service.component import AIR_SPECIFIC_HEAT_J_PER_KG_K, WATER_SPECIFIC_HEAT_J_PER_KG_K, ComponentModel
from service.effects.duct_heat_exchange import DuctHeatExchange
from service.effects.fan_motor_heat import FanMotorHeat
from service.effects.first_order_lag import FirstOrderLag
from service.effects.heat_to_air import ConstantHeatGain
from service.effects.sensor_offset import SensorOffset
from service.effects.valve_leakage import ValveLeakage
from service.effects.valve_stuck import ValveStuck
from service.fan import Fan
from service.hot_water_loop import HotWaterLoop, counterflow_effectiveness
from service.measuring_device import MeasuringDevice
from service.pi_controller import PIController

MODELS = [Fan, HotWaterLoop, PIController, MeasuringDevice, FanMotorHeat, DuctHeatExchange, FirstOrderLag,
          ConstantHeatGain, SensorOffset, ValveLeakage, ValveStuck]
INPUTS = {"air_volume_flow": 1.2, "inlet_air_temperature": 5.0, "valve_position": 0.4,
          "supply_water_temperature": 65.0, "air_mass_flow": 1.5, "setpoint": 21.0, "measured_value": 19.0,
          "value_in": 20.0, "electric_power": 1500.0, "ambient_temperature": 15.0}


def _params(cls, n, which="default"):
    return {p.name: np.full(n, getattr(p, which)) for p in cls.parameters}


def _run(cls, params, inputs, steps=20, dt=300.0):
    model = cls()
    state = model.initial_state(params, inputs, dt)
    return [model.step(params, inputs, state, dt) for _ in range(steps)]


@pytest.mark.parametrize("cls", MODELS, ids=lambda c: c.__name__)
def test_contract_ensemble_equals_member_by_member_and_corners_are_finite(cls):
    assert issubclass(cls, ComponentModel)
    rng = np.random.default_rng(0)
    n = 5
    params = {p.name: p.lower + rng.random(n) * (p.upper - p.lower) for p in cls.parameters}
    inputs = {p.name: np.full(n, INPUTS[p.name]) for p in cls.inputs}
    together = _run(cls, params, inputs)[-1]
    for i in range(n):
        alone = _run(cls, {k: v[i:i + 1] for k, v in params.items()}, {k: v[i:i + 1] for k, v in inputs.items()})[-1]
        for port, value in together.items():
            assert value[i] == pytest.approx(alone[port][0], rel=1e-12, abs=1e-12)
    for corner in ("lower", "upper"):
        out = _run(cls, _params(cls, 1, corner), {k: v[:1] for k, v in inputs.items()})[-1]
        assert all(np.isfinite(v).all() for v in out.values())


@pytest.mark.parametrize("cls", [c for c in MODELS if any(p.null is not None for p in c.parameters)], ids=lambda c: c.__name__)
def test_effects_vanish_at_their_null(cls):
    params = {p.name: np.array([p.null if p.null is not None else p.default]) for p in cls.parameters}
    inputs = {p.name: np.array([INPUTS[p.name]]) for p in cls.inputs}
    assert _run(cls, params, inputs)[-1]["value_out"][0] == pytest.approx(INPUTS["value_in"])


def test_fan_at_nominal_flow_draws_nominal_power_times_the_curve_sum():
    params = _params(Fan, 1)
    out = _run(Fan, params, {"air_volume_flow": np.array([1.5]), "inlet_air_temperature": np.array([4.0])}, steps=1)[0]
    c = [params[f"c{i}"][0] for i in range(1, 5)]
    assert out["electric_power"][0] == pytest.approx(1800.0 * sum(c))
    assert out["outlet_air_mass_flow"][0] == pytest.approx(1.204 * 1.5)
    assert out["outlet_air_temperature"][0] == 4.0


def test_counterflow_effectiveness_limits():
    assert counterflow_effectiveness(np.array([1.0]), np.array([0.0]))[0] == pytest.approx(1 - np.exp(-1))
    assert counterflow_effectiveness(np.array([1.0]), np.array([1.0]))[0] == pytest.approx(0.5)
    assert counterflow_effectiveness(np.array([50.0]), np.array([0.5]))[0] == pytest.approx(1.0, abs=1e-9)


def _loop(position, steps=60):
    params = _params(HotWaterLoop, 1)
    inputs = {"valve_position": np.array([position]), "supply_water_temperature": np.array([65.0]),
              "inlet_air_temperature": np.array([5.0]), "air_mass_flow": np.array([1.5])}
    return _run(HotWaterLoop, params, inputs, steps=steps)[-1]


def test_closed_valve_gives_no_flow_and_no_heat():
    out = _loop(0.0)
    assert out["water_mass_flow"][0] == 0.0 and out["heat_rate"][0] == 0.0
    assert out["outlet_air_temperature"][0] == pytest.approx(5.0)


def test_steady_state_energy_balance_within_half_a_percent():
    out = _loop(0.6, steps=400)
    air = 1.5 * AIR_SPECIFIC_HEAT_J_PER_KG_K * (out["outlet_air_temperature"][0] - 5.0)
    water = out["water_mass_flow"][0] * WATER_SPECIFIC_HEAT_J_PER_KG_K * (out["inlet_water_temperature"][0] - out["outlet_water_temperature"][0])
    assert air > 1000.0
    assert air == pytest.approx(water, rel=0.005)
    assert air == pytest.approx(out["heat_rate"][0], rel=0.005)


def test_more_opening_gives_more_heat():
    heats = [_loop(u, steps=200)["heat_rate"][0] for u in (0.1, 0.3, 0.6, 1.0)]
    assert heats == sorted(heats) and heats[0] > 0


def test_pi_controller_sign_limits_and_anti_windup():
    params = {"proportional_gain": np.array([0.02]), "integral_time": np.array([600.0])}
    controller = PIController()
    cold = {"setpoint": np.array([21.0]), "measured_value": np.array([15.0])}
    state = controller.initial_state(params, cold, 300.0)
    first = controller.step(params, cold, state, 300.0)["control_signal"][0]
    assert first == pytest.approx(0.02 * 6.0)  # reverse acting: too cold → opens
    for _ in range(500):  # a long saturation
        out = controller.step(params, cold, state, 300.0)["control_signal"][0]
    assert out == 1.0
    warm = {"setpoint": np.array([21.0]), "measured_value": np.array([21.5])}
    steps_to_leave = next(k for k in range(1, 100) if controller.step(params, warm, state, 300.0)["control_signal"][0] < 1.0)
    # without anti-windup the integral of 500 saturated steps would hold it at 1 for hundreds of steps
    assert steps_to_leave <= 40
