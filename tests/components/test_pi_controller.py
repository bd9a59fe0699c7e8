"""PI controller: reverse and direct action, the integral by hand, output limits, back-calculation anti-windup."""

import numpy as np
import pytest

from service.components.pi_controller import DirectActingPIController, PIController

PARAMS = {"proportional_gain": np.array([0.02]), "integral_time": np.array([600.0])}


def _signals(setpoint, measured):
    return {"setpoint": np.array([setpoint]), "measured_value": np.array([measured])}


def _drive(controller, state, setpoint, measured, steps, dt=300.0):
    return [controller.step(PARAMS, _signals(setpoint, measured), state, dt)["control_signal"][0] for _ in range(steps)]


@pytest.mark.parametrize("model, opening_error", [(PIController, -1.0), (DirectActingPIController, +1.0)],
                         ids=["reverse acting: opens below the setpoint", "direct acting: opens above it"])
def test_the_action_with_the_integral_by_hand(model, opening_error):
    # |e| = 1 K, K_p = 0.02 /K, T_i = 600 s, Δt = 60 s: u_k = 0.02·(1 + k·60/600) (integral before its update)
    controller = model()
    measured = 21.0 + opening_error
    state = controller.initial_state(PARAMS, _signals(21.0, measured), 60.0)
    signals = _drive(controller, state, 21.0, measured, 11, dt=60.0)
    np.testing.assert_allclose(signals, [0.02 * (1 + 0.1 * k) for k in range(11)], rtol=1e-12)
    closing = model()
    state = closing.initial_state(PARAMS, _signals(21.0, 21.0 - opening_error), 60.0)
    assert _drive(closing, state, 21.0, 21.0 - opening_error, 1)[0] == 0.0  # the other side of the setpoint: closes


def test_output_stays_within_zero_and_one():
    controller = PIController()
    state = controller.initial_state(PARAMS, _signals(21.0, 0.0), 300.0)
    signals = _drive(controller, state, 21.0, 0.0, 50) + _drive(controller, state, 21.0, 40.0, 50)
    assert min(signals) == 0.0 and max(signals) == 1.0


def test_a_long_saturation_does_not_delay_the_recovery():
    """500 steps (42 h) at e = +6 K hold the output at 1. Back-calculation (T_t = max(T_i, Δt) =
    600 s) drives v = K_p·(e + I/T_i) to its fixed point 1 + K_p·e·T_t/T_i = 1.12, where the integral
    part K_p·I/T_i is the limit, 1: I = T_i/K_p = 30 000 K·s. With e = −0.5 K the output is then
    0.02·(−0.5 + 50) = 0.99 < 1 at the first step. (Without anti-windup the integral, 900 000 K·s,
    would hold the output at 1 for ≈ 5800 steps.)"""
    controller = PIController()
    state = controller.initial_state(PARAMS, _signals(21.0, 15.0), 300.0)
    assert _drive(controller, state, 21.0, 15.0, 500)[-1] == 1.0
    assert state["integral"][0] == pytest.approx(600.0 / 0.02, rel=1e-9)
    assert _drive(controller, state, 21.0, 21.5, 1)[0] == pytest.approx(0.99, rel=1e-9)


def test_the_output_is_continuous_in_the_integral_time_across_saturation():
    """T_i over its prior range in steps of 0.1 s, as one ensemble, through a saturation and a
    recovery: neighbouring trajectories differ by little everywhere, so the calibration cost has no
    jumps. (Conditional integration, which switches the integral's increment on or off by whether the
    output is past its limit, differed by 0.08 somewhere on this grid: a step whose increment flipped.)"""
    measured = np.r_[np.full(80, 15.0), np.full(30, 21.5), np.full(30, 19.0)]
    integral_time = np.linspace(600.0, 3600.0, 30_001)
    params = {"proportional_gain": np.full_like(integral_time, 0.03), "integral_time": integral_time}
    controller = PIController()

    def signals(y):
        return {"setpoint": np.full_like(integral_time, 21.0), "measured_value": np.full_like(integral_time, y)}

    state = controller.initial_state(params, signals(measured[0]), 300.0)
    outputs = np.array([controller.step(params, signals(y), state, 300.0)["control_signal"] for y in measured])
    # every run saturates at e = +6 K and leaves the limit at e = −0.5 K
    assert (outputs[:80] == 1.0).any(axis=0).all() and (outputs[80:110] < 1.0).any(axis=0).all()
    assert np.abs(np.diff(outputs, axis=1)).max() < 1e-3


def test_a_long_closure_does_not_delay_the_opening():
    controller = PIController()
    state = controller.initial_state(PARAMS, _signals(21.0, 27.0), 300.0)
    assert _drive(controller, state, 21.0, 27.0, 500)[-1] == 0.0
    assert _drive(controller, state, 21.0, 20.5, 1)[0] == pytest.approx(0.02 * 0.5, rel=1e-12)
