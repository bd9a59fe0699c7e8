"""Hot-water loop: hydraulics by hand, closed valve, steady-state energy balance, the documented lags."""

import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.special import gammaincc

from service.components.component import AIR_SPECIFIC_HEAT_J_PER_KG_K, WATER_SPECIFIC_HEAT_J_PER_KG_K
from service.components.hot_water_loop import (
    REFERENCE_WATER_MASS_FLOW,
    SUPPLY_PIPE_TANKS,
    HotWaterLoop,
    advance_tank_chain,
    valve_flow_share,
)

DT = 60.0


def _inputs(valve, supply=65.0, air_in=5.0, air_flow=1.5):
    return {"valve_position": np.array([valve]), "supply_water_temperature": np.array([supply]),
            "inlet_air_temperature": np.array([air_in]), "air_mass_flow": np.array([air_flow])}


def _steps(params, state, inputs, steps):
    model = HotWaterLoop()
    return [{k: v[0] for k, v in model.step(params, inputs, state, DT).items()} for _ in range(steps)]


def test_water_flow_by_hand(run_model, params_for):
    # defaults K_v = 2.5, K_v,loop = 3.3 m³/h, Δp = 0.45 bar, R = 25; u = 0.6:
    # φ = 25^(−0.4) − 0.4/25 = 0.259946, V̇ = sqrt(0.45 / (1/(2.5·φ)² + 1/3.3²)) m³/h, ṁ_w = 988·V̇/3600
    out = run_model(HotWaterLoop, params_for(HotWaterLoop), _inputs(0.6))[0]
    share = 25.0**-0.4 - 0.4 / 25.0
    by_hand = 988.0 / 3600.0 * math.sqrt(0.45 / (1 / (2.5 * share) ** 2 + 1 / 3.3**2))
    assert share == pytest.approx(0.259946, abs=1e-6)
    assert out["water_mass_flow"][0] == pytest.approx(by_hand, rel=1e-12)
    # R = 1 is a linear valve: K_v·u = 1.5 m³/h, V̇ = 0.91604 m³/h, ṁ_w = 0.25140 kg/s
    linear = run_model(HotWaterLoop, params_for(HotWaterLoop, valve_rangeability=1.0), _inputs(0.6))[0]
    assert linear["water_mass_flow"][0] == pytest.approx(0.25140, abs=1e-5)


@pytest.mark.parametrize("rangeability", [1.0, 25.0, 50.0, 100.0])
def test_the_valve_characteristic_shuts_tight_opens_fully_and_is_equal_percentage_in_its_middle(rangeability):
    position = np.linspace(0.0, 1.0, 1001)
    share = valve_flow_share(position, np.array(rangeability))
    assert share[0] == pytest.approx(0.0, abs=1e-15) and share[-1] == pytest.approx(1.0, rel=1e-15)
    assert np.all(np.diff(share) > 0.0)
    if rangeability == 1.0:
        np.testing.assert_allclose(share, position, atol=1e-15)
    else:  # each tenth of the stroke above 60 % multiplies the flow by R^0.1 within 5 % (the −(1−u)/R term)
        ratio = share[600:1001:100][1:] / share[600:1001:100][:-1]
        np.testing.assert_allclose(ratio, rangeability**0.1, rtol=0.05)


def test_closed_valve_gives_no_flow_and_no_heat(run_model, params_for):
    out = run_model(HotWaterLoop, params_for(HotWaterLoop), _inputs(0.0), steps=60)[-1]
    assert out["water_mass_flow"][0] == 0.0 and out["heat_rate"][0] == 0.0
    assert out["outlet_air_temperature"][0] == pytest.approx(5.0, abs=1e-12)


#: Standing water that loses no heat: the coil's own balances, without the pipes' loss.
NO_LOSS = {"standing_water_time_constant": 1e15}


@pytest.mark.parametrize("air_flow", [1.5, 0.05])  # 0.05 kg/s: a fan at low speed, below the old 0.1 kg/s floor
def test_steady_state_energy_balance_within_half_a_percent(run_model, params_for, air_flow):
    out = run_model(HotWaterLoop, params_for(HotWaterLoop, **NO_LOSS), _inputs(0.6, air_flow=air_flow), steps=200)[-1]
    air = air_flow * AIR_SPECIFIC_HEAT_J_PER_KG_K * (out["outlet_air_temperature"][0] - 5.0)
    water = out["water_mass_flow"][0] * WATER_SPECIFIC_HEAT_J_PER_KG_K * (
        out["inlet_water_temperature"][0] - out["outlet_water_temperature"][0])
    assert air > 2000.0
    assert air == pytest.approx(water, rel=0.005)
    assert air == pytest.approx(out["heat_rate"][0], rel=0.005)


def test_more_opening_gives_more_heat(run_model, params_for):
    params = params_for(HotWaterLoop)
    heats = [run_model(HotWaterLoop, params, _inputs(u))[0]["heat_rate"][0] for u in (0.05, 0.3, 0.6, 1.0)]
    assert heats == sorted(heats) and heats[0] > 0


def test_heat_rate_follows_a_valve_step_with_the_metal_time_constant(params_for):
    """Started in steady state at u = 0.3, the valve steps to 0.6: the water inlet is already at the
    supply temperature and the flows are constant, so Q_k = Q∞ + (Q₀ − Q∞)·(1 − a)^{k+1},
    a = 1 − e^{−Δt/τ_metal} (the lag is reported after its update)."""
    params = params_for(HotWaterLoop, **NO_LOSS)
    model = HotWaterLoop()
    q0 = model.initial_state(params, _inputs(0.3), DT)["heat_rate"][0]
    q_end = model.initial_state(params, _inputs(0.6), DT)["heat_rate"][0]
    state = model.initial_state(params, _inputs(0.3), DT)
    a = 1.0 - math.exp(-DT / 180.0)
    heats = [out["heat_rate"] for out in _steps(params, state, _inputs(0.6), 10)]
    expected = [q_end + (q0 - q_end) * (1.0 - a) ** (k + 1) for k in range(10)]
    assert q_end > q0 * 1.1
    np.testing.assert_allclose(heats, expected, rtol=1e-9)


def test_a_supply_step_reaches_the_coil_as_a_front_after_the_pipe_s_transport_time(params_for):
    """A supply step 65 → 75 °C through N tanks in series of total transport time τ = τ_pipe·ṁ_ref/ṁ_w
    arrives as the Erlang distribution's CDF: T_w,in(t) = 75 − 10·Q(N, N·t/τ) (Q the regularised
    upper incomplete gamma function), exact at every step; half the step is there within a tenth of
    τ of the transport time, and under 2 % of it before half of it."""
    params = params_for(HotWaterLoop, supply_pipe_time_constant=300.0, **NO_LOSS)
    state = HotWaterLoop().initial_state(params, _inputs(0.6), DT)
    outs = _steps(params, state, _inputs(0.6, supply=75.0), 60)
    transport_s = 300.0 * REFERENCE_WATER_MASS_FLOW / outs[0]["water_mass_flow"]
    t = DT * np.arange(1, 61)
    inlet = np.array([o["inlet_water_temperature"] for o in outs])
    np.testing.assert_allclose(inlet, 75.0 - 10.0 * gammaincc(SUPPLY_PIPE_TANKS, SUPPLY_PIPE_TANKS * t / transport_s),
                               rtol=1e-12)
    half = t[np.argmax(inlet >= 70.0)]
    assert 2 * DT < transport_s < t[-1] / 2
    assert abs(half - transport_s) < 0.1 * transport_s + DT
    assert inlet[t < 0.5 * transport_s].max() < 65.2  # under 2 % of the step


def test_standing_water_cools_to_its_surroundings_with_tau_loss_and_moves_again_with_the_flow(params_for):
    """Valve shut after a steady state at u = 1: no flow, so the inlet and the outlet water approach
    T_amb = 18 °C exactly as T_amb + (T₀ − T_amb)·e^{−t/τ_loss}, τ_loss = 4 h (hours, where the
    transport time τ·ṁ_ref/ṁ_w would be infinite); opened again, hot water is back within minutes."""
    params = params_for(HotWaterLoop)
    model = HotWaterLoop()
    state = model.initial_state(params, _inputs(1.0), DT)
    start = {"inlet_water_temperature": 18.0 + state["supply_pipe_water_excess"][0, -1],
             "outlet_water_temperature": state["outlet_water_temperature"][0]}
    shut = _steps(params, state, _inputs(0.0), 240)  # four hours
    decay = math.exp(-240 * DT / 14400.0)
    for port, t0 in start.items():
        assert shut[-1][port] == pytest.approx(18.0 + (t0 - 18.0) * decay, rel=1e-9)
    assert start["inlet_water_temperature"] > 60.0 and shut[-1]["inlet_water_temperature"] < 40.0
    opened = _steps(params, state, _inputs(1.0), 10)
    assert opened[-1]["inlet_water_temperature"] > 60.0


def test_the_reported_valve_position_is_the_clipped_command(run_model, params_for):
    for command, reached in ((1.3, 1.0), (-0.1, 0.0), (0.42, 0.42)):
        assert run_model(HotWaterLoop, params_for(HotWaterLoop), _inputs(command))[0]["valve_position"][0] == reached


@pytest.mark.parametrize(("rate_per_s", "loss_per_s"), [(0.02, 1e-4), (0.0, 1e-4), (2.0, 0.0)])
def test_the_tank_chain_advances_as_its_matrix_exponential(rate_per_s, loss_per_s):
    """dθ/dt = A·θ + b·θ₀ (A = −(k + λ)·I + k·S, S the shift, b = k·e₁), held θ₀, against scipy's
    expm of the system augmented by θ₀ (no flow: every tank only loses heat)."""
    n, dt = SUPPLY_PIPE_TANKS, 120.0
    system = np.zeros((n + 1, n + 1))
    system[:n, :n] = -(rate_per_s + loss_per_s) * np.eye(n) + rate_per_s * np.eye(n, k=-1)
    system[0, n] = rate_per_s
    start = np.linspace(30.0, 5.0, n)
    expected = (expm(system * dt) @ np.append(start, 40.0))[:n]
    advanced = advance_tank_chain(start[None, :], np.array([40.0]), np.array([rate_per_s * dt]),
                                  np.array([loss_per_s * dt]))[0]
    np.testing.assert_allclose(advanced, expected, rtol=1e-10, atol=1e-12)
