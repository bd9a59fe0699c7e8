"""A duct's (or a casing's) heat exchange with its surroundings, measured or not (hand-computed values)."""

import math

import numpy as np
import pytest

from service.components.effects.duct_heat_exchange import DuctHeatExchange, DuctHeatExchangeUnmeasured


def test_air_approaches_its_surroundings_by_the_exchangers_exponential(run_model, params_for):
    # UA 150 W/K, 1.2 kg/s at 1006 J/(kg·K): 30 − (30 − 14)·(1 − e^(−150/1207.2)) = 28.130 °C
    inputs = {"value_in": np.array([30.0]), "ambient_temperature": np.array([14.0]), "air_mass_flow": np.array([1.2])}
    out = run_model(DuctHeatExchange, params_for(DuctHeatExchange, duct_conductance=150.0), inputs)[0]["value_out"][0]
    assert out == pytest.approx(14.0 + 16.0 * math.exp(-150.0 / (1.2 * 1006.0)), rel=1e-12)
    assert out == pytest.approx(28.130, abs=1e-3)


def test_unmeasured_surroundings_are_a_parameter_that_acts_as_the_measured_temperature_would(run_model, params_for):
    flow, inlet = np.array([0.3, 1.2, 2.4]), np.array([30.0, 21.0, 16.0])
    measured = run_model(DuctHeatExchange, params_for(DuctHeatExchange, 3, duct_conductance=150.0),
                         {"value_in": inlet, "ambient_temperature": np.full(3, 14.0), "air_mass_flow": flow})
    params = params_for(DuctHeatExchangeUnmeasured, 3, duct_conductance=150.0, surroundings_temperature=14.0)
    unmeasured = run_model(DuctHeatExchangeUnmeasured, params, {"value_in": inlet, "air_mass_flow": flow})
    np.testing.assert_allclose(unmeasured[0]["value_out"], measured[0]["value_out"], rtol=1e-12)


def test_without_conductance_the_surroundings_do_nothing(run_model, params_for):
    inputs = {"value_in": np.array([30.0, 30.0]), "air_mass_flow": np.array([1.2, 1.2])}
    params = params_for(DuctHeatExchangeUnmeasured, 2, duct_conductance=0.0)  # its null
    params["surroundings_temperature"] = np.array([-20.0, 50.0])
    np.testing.assert_array_equal(run_model(DuctHeatExchangeUnmeasured, params, inputs)[0]["value_out"], [30.0, 30.0])
