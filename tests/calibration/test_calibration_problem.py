"""The calibration problem contract: validation messages, default scales, residuals, output checks."""

from __future__ import annotations

import numpy as np
import pytest

from service.calibration.problem import CalibrationProblem, default_target_scale


def linear_simulate(theta):
    t = np.arange(4.0)
    return {"y": theta[:, :1] + theta[:, 1:2] * t, "z": np.repeat(theta[:, :1], 4, axis=1)}


def make(**changes):
    arguments = dict(
        parameter_names=("a", "b"),
        lower=[0.0, -1.0],
        upper=[2.0, 1.0],
        simulate=linear_simulate,
        observed={"y": [1.0, 1.5, np.nan, 2.5], "z": [1.0, 1.1, 0.9, 1.0]},
        target_scales={"y": 0.5, "z": 0.1},
    )
    arguments.update(changes)
    return CalibrationProblem(**arguments)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"observed": {"y": [np.nan] * 4}}, "target y has no measurements in the window"),
        ({"lower": [2.0, -1.0]}, "parameter a: lower bound 2 is not below upper bound 2"),
        ({"upper": [2.0]}, r"upper has shape \(1,\), expected \(2,\)"),
        ({"default": [1.0, 3.0]}, r"parameter b: default 3 outside bounds \[-1, 1\]"),
        ({"observed": {"y": [1.0, 2.0, 3.0, 4.0], "z": [1.0, 2.0]}}, r"observed\['z'\] has shape \(2,\), expected \(4,\)"),
        ({"observed": {"y": [[1.0, 2.0]]}}, r"observed\['y'\] has shape \(1, 2\), expected \(n_steps,\)"),
        ({"gp_inputs": np.zeros((3, 2))}, r"gp_inputs has shape \(3, 2\), expected \(4, n_features\)"),
        ({"target_scales": {"y": 0.0}}, r"target_scales\['y'\] = 0 must be positive"),
        ({"units": {"w": "W"}}, "units names targets without observations: w"),
        ({"parameter_names": ("a", "a")}, "duplicate parameter names: a"),
    ],
)
def test_invalid_problems_are_refused_with_a_message_naming_the_problem(changes, message):
    with pytest.raises(ValueError, match=message):
        make(**changes)


def test_weighted_residuals_skip_unmeasured_points_and_divide_by_the_scale():
    problem = make()
    outputs = problem.run(np.array([[1.0, 0.5], [0.0, 0.0]]))
    residuals = problem.weighted_residuals(outputs)
    # member 0 reproduces y exactly; z = 1 everywhere → (0, 0.1, −0.1, 0) / 0.1
    np.testing.assert_allclose(residuals[0], [0, 0, 0, 0, 1, -1, 0], atol=1e-12)
    np.testing.assert_allclose(residuals[1], [2.0, 3.0, 5.0, 10.0, 11.0, 9.0, 10.0])
    assert problem.n_observations == 7


def test_run_names_the_target_and_shape_when_simulate_misbehaves():
    problem = make(simulate=lambda theta: {"y": np.zeros((theta.shape[0], 3)), "z": np.zeros((theta.shape[0], 4))})
    with pytest.raises(ValueError, match=r"target 'y' has shape \(2, 3\), expected \(2, 4\)"):
        problem.run(np.ones((2, 2)))
    with pytest.raises(ValueError, match="no output for target 'z'"):
        make(simulate=lambda theta: {"y": np.zeros((1, 4))}).run(np.ones((1, 2)))
    with pytest.raises(ValueError, match=r"theta has shape \(3,\), expected \(n_ensemble, 2\)"):
        problem.run(np.ones(3))


def test_unit_cube_round_trip():
    problem = make()
    np.testing.assert_allclose(problem.to_unit([1.0, 0.5]), [0.5, 0.75])
    np.testing.assert_allclose(problem.from_unit(problem.to_unit([[0.3, -0.2]])), [[0.3, -0.2]])


def test_default_scale_is_the_robust_spread_with_fallbacks_and_floors():
    rng = np.random.default_rng(0)
    spiked = np.concatenate([rng.normal(50.0, 2.0, 2000), np.full(20, 5000.0), [np.nan]])
    assert default_target_scale(spiked, "W") == pytest.approx(2.0, rel=0.05)  # 1 % spikes do not inflate it
    # a fan at its weekend speed for 54 % of the window and at its weekday speeds for the rest: the
    # scale sees the swing between the modes (1.4826·MAD saw only the weekend's 6 W)
    weekend, weekdays = rng.normal(106.0, 4.0, 290), rng.uniform(150.0, 1400.0, 250)
    fan = np.concatenate([weekend, weekdays])
    scale = default_target_scale(fan, "W")
    assert scale == pytest.approx((np.percentile(fan, 95) - np.percentile(fan, 5)) / 3.2897)
    assert scale > 300.0
    shut_valve = np.array([0.0] * 99 + [1.0])  # shut 99 % of the time: range 0 → plain std
    assert default_target_scale(shut_valve, "1") == pytest.approx(np.std(shut_valve))
    flat_temperature = np.full(10, 21.0)
    assert default_target_scale(flat_temperature, "degC") == pytest.approx(0.1)
    flat_power = np.full(10, 2000.0)
    assert default_target_scale(flat_power, "W") == pytest.approx(20.0)
    with pytest.raises(ValueError, match="target p is constant at 0"):
        default_target_scale(np.zeros(5), "W", "p")


def test_given_scales_are_kept_and_missing_ones_defaulted():
    problem = make(target_scales={"y": 0.5}, units={"z": "degC"})
    assert problem.target_scales["y"] == 0.5
    assert problem.target_scales["z"] == pytest.approx(0.1)  # spread 0.07 is below the 0.1 K floor
    assert problem.units == {"y": "", "z": "degC"}
