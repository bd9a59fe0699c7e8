"""PI controller: reverse and direct action, the integral by hand, output limits, conditional-integration anti-windup."""

import numpy as np
import pytest

from service.pi_controller import DirectActingPIController, PIController

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
    """500 steps (42 h) at e = +6 K hold the output at 1. Conditional integration stops the integral
    one step past saturation: I ≤ T_i·(1/K_p − e) + e·Δt = 26 400 + 1800 K·s, so with e = −0.5 K the
    output is at most 0.02·(−0.5 + 28 200/600) = 0.93 < 1 at the first step. (Without anti-windup the
    integral, 900 000 K·s, would hold the output at 1 for ≈ 5800 steps.)"""
    controller = PIController()
    state = controller.initial_state(PARAMS, _signals(21.0, 15.0), 300.0)
    assert _drive(controller, state, 21.0, 15.0, 500)[-1] == 1.0
    assert state["integral"][0] <= 600.0 * (1 / 0.02 - 6.0) + 6.0 * 300.0
    recovery = _drive(controller, state, 21.0, 21.5, 1)[0]
    assert recovery <= 0.93 + 1e-12


def test_a_long_closure_does_not_delay_the_opening():
    controller = PIController()
    state = controller.initial_state(PARAMS, _signals(21.0, 27.0), 300.0)
    assert _drive(controller, state, 21.0, 27.0, 500)[-1] == 0.0
    assert _drive(controller, state, 21.0, 20.5, 1)[0] == pytest.approx(0.02 * 0.5, rel=1e-12)
