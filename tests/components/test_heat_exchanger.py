"""ε-NTU relations: textbook limits and hand-computed values."""

import numpy as np
import pytest

from service.components.heat_exchanger import coil_heat_rate_w, counterflow_effectiveness, series_film_ua_w_per_k


def test_counterflow_effectiveness_limits_and_a_textbook_value():
    ntu = np.array([0.3, 1.0, 4.0])
    np.testing.assert_allclose(counterflow_effectiveness(ntu, np.zeros(3)), 1.0 - np.exp(-ntu), rtol=1e-12)
    np.testing.assert_allclose(counterflow_effectiveness(ntu, np.ones(3)), ntu / (1.0 + ntu), atol=1e-6)
    assert counterflow_effectiveness(np.array([60.0]), np.array([0.5]))[0] == pytest.approx(1.0, abs=1e-12)
    # NTU = 2, C_r = 0.5: ε = (1 − e^{−1}) / (1 − 0.5·e^{−1}) = 0.63212 / 0.81606 = 0.77460
    assert counterflow_effectiveness(np.array([2.0]), np.array([0.5]))[0] == pytest.approx(0.77460, abs=5e-6)


def test_effectiveness_rises_with_ntu_and_falls_with_the_capacity_ratio():
    ntu = np.linspace(0.05, 6.0, 40)
    for ratio in (0.0, 0.4, 0.9, 1.0):
        assert np.all(np.diff(counterflow_effectiveness(ntu, np.full(40, ratio))) > 0)
    ratios = np.linspace(0.0, 1.0, 21)
    assert np.all(np.diff(counterflow_effectiveness(np.full(21, 1.5), ratios)) < 0)


def test_series_film_conductances():
    # hA_w = 1000 W/K at half its reference flow: 1000·0.5^0.8 = 574.35 W/K; with 3000 W/K in series: 482.06 W/K
    ua = series_film_ua_w_per_k(water_conductance_w_per_k=np.array([1000.0, 1000.0, 1000.0]),
                                water_flow_ratio=np.array([1.0, 0.5, 0.0]),
                                air_conductance_w_per_k=np.array([3000.0, 3000.0, 3000.0]),
                                air_flow_ratio=np.array([1.0, 1.0, 1.0]))
    np.testing.assert_allclose(ua[:2], [750.0, 482.06], rtol=1e-5)
    assert 0.0 <= ua[2] < 1e-3


def test_coil_heat_rate_sign_bound_and_zero_flow():
    c_water, c_air = np.array([800.0, 800.0, 0.0]), np.array([1500.0, 1500.0, 1500.0])
    q = coil_heat_rate_w(np.full(3, 5000.0), water_capacity_w_per_k=c_water, air_capacity_w_per_k=c_air,
                         water_inlet_temperature=np.array([60.0, 7.0, 60.0]), air_inlet_temperature=np.full(3, 20.0))
    assert q[0] > 0 > q[1]
    assert q[0] <= 800.0 * 40.0 and -q[1] <= 800.0 * 13.0  # |Q| ≤ C_min·|ΔT|
    assert abs(q[2]) < 1e-6  # no water flow: no heat
