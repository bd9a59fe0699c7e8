"""Command-driven water coil: a hand ε-NTU number, heating and cooling, closed valve, no air flow."""

import numpy as np
import pytest

from service.components.component import AIR_SPECIFIC_HEAT_J_PER_KG_K
from service.components.water_coil import CoolingWaterCoil, HeatingWaterCoil, WaterCoil


def _coil(run_model, cls, params, valve, air_in, air_flow):
    n = np.size(valve)
    inputs = {"valve_position": np.atleast_1d(np.asarray(valve, float)),
              "inlet_air_temperature": np.full(n, air_in), "air_mass_flow": np.full(n, air_flow)}
    return run_model(cls, params, inputs)[0]


def test_heating_coil_against_a_hand_epsilon_ntu_number(run_model, params_for):
    # defaults: T_w = 60 °C, ṁ_w,max = 0.4 kg/s, hA_w = hA_a = 2000 W/K; valve open, 2 kg/s of air at 10 °C.
    # C_w = 0.4·4181 = 1672.4 W/K = C_min, C_a = 2·1006 = 2012 W/K, C_r = 0.83121,
    # UA = 1/(1/2000 + 1/2000) = 1000 W/K, NTU = 0.59794,
    # ε = (1 − e^{−0.59794·0.16879}) / (1 − 0.83121·e^{−0.59794·0.16879}) = 0.38619,
    # Q = 0.38619·1672.4·(60 − 10) = 32.29 kW, T_a,out = 10 + 32 293/2012 = 26.05 °C.
    out = _coil(run_model, HeatingWaterCoil, params_for(HeatingWaterCoil), 1.0, 10.0, 2.0)
    assert out["heat_rate"][0] == pytest.approx(32293.0, rel=1e-4)
    assert out["outlet_air_temperature"][0] == pytest.approx(26.050, abs=2e-3)


def test_cooling_coil_at_part_load_against_a_hand_number(run_model, params_for):
    # T_w = 7 °C, valve half open: C_w = 0.5·0.4·4181 = 836.2 W/K; 1 kg/s of air at 26 °C: C_a = 1006 W/K.
    # hA_w·0.5^0.8 = hA_a·0.5^0.8 = 1148.70 W/K → UA = 574.35 W/K, NTU = 0.68686, C_r = 0.83121,
    # ε = 0.42138, Q = 0.42138·836.2·(7 − 26) = −6.695 kW, T_a,out = 26 − 6695/1006 = 19.35 °C.
    out = _coil(run_model, CoolingWaterCoil, params_for(CoolingWaterCoil), 0.5, 26.0, 1.0)
    assert out["heat_rate"][0] == pytest.approx(-6694.8, rel=1e-4)
    assert out["outlet_air_temperature"][0] == pytest.approx(19.345, abs=2e-3)


def test_closed_valve_gives_no_heat_and_passes_the_air_unchanged(run_model, params_for):
    for cls in (HeatingWaterCoil, CoolingWaterCoil, WaterCoil):
        out = _coil(run_model, cls, params_for(cls, n=2), [0.0, -0.02], 18.0, 1.2)
        np.testing.assert_array_equal(out["heat_rate"], 0.0)
        np.testing.assert_array_equal(out["outlet_air_temperature"], 18.0)


def test_outlet_temperature_is_the_heat_balance_and_stays_between_the_inlets(run_model, params_for):
    valve = np.linspace(0.05, 1.0, 20)
    for cls, air_in in ((HeatingWaterCoil, 8.0), (CoolingWaterCoil, 27.0)):
        params = params_for(cls, n=20)
        out = _coil(run_model, cls, params, valve, air_in, 1.3)
        np.testing.assert_allclose(out["outlet_air_temperature"] - air_in,
                                   out["heat_rate"] / (1.3 * AIR_SPECIFIC_HEAT_J_PER_KG_K), rtol=1e-12)
        low, high = sorted((air_in, params["supply_water_temperature"][0]))
        assert np.all((out["outlet_air_temperature"] >= low) & (out["outlet_air_temperature"] <= high))
        assert np.all(np.diff(np.abs(out["heat_rate"])) > 0)  # more opening, more heat


def test_stagnant_air_leaves_at_the_water_temperature(run_model, params_for):
    out = _coil(run_model, HeatingWaterCoil, params_for(HeatingWaterCoil), 1.0, 15.0, 0.0)
    assert abs(out["heat_rate"][0]) < 1e-3
    assert out["outlet_air_temperature"][0] == pytest.approx(60.0, abs=1e-6)


def test_heating_and_cooling_coils_differ_only_in_the_supply_water_prior():
    for cls in (HeatingWaterCoil, CoolingWaterCoil):
        assert cls.step is WaterCoil.step and (cls.inputs, cls.outputs) == (WaterCoil.inputs, WaterCoil.outputs)
        assert cls.parameters[1:] == WaterCoil.parameters[1:]
    assert HeatingWaterCoil.parameter("supply_water_temperature").lower > 30.0
    assert CoolingWaterCoil.parameter("supply_water_temperature").upper < 20.0


def test_a_fed_supply_water_temperature_drives_the_heat_and_the_parameter_stands_in_otherwise(run_model, params_for):
    base = {"valve_position": np.array([0.6]), "inlet_air_temperature": np.array([15.0]),
            "air_mass_flow": np.array([0.8])}
    params = params_for(HeatingWaterCoil, supply_water_temperature=60.0)

    def heat(inputs):
        return run_model(HeatingWaterCoil, params, inputs)[0]["heat_rate"][0]

    from_parameter = heat(base)
    assert heat({**base, "supply_water_temperature": np.array([60.0])}) == pytest.approx(from_parameter, rel=1e-12)
    # ε-NTU: the heat is proportional to the inlet temperature difference at a fixed flow
    assert heat({**base, "supply_water_temperature": np.array([80.0])}) == pytest.approx(
        from_parameter * (80.0 - 15.0) / (60.0 - 15.0), rel=1e-9)
