"""Shared harness of the component tests.

* ``component_class``: a test that takes this argument runs once per model class the signature
  library names (components and effects), so a new model is checked by adding its signature file;
  ``effect_class`` likewise over the effects (:class:`service.components.component.SplicedEffect`);
* ``run_model``: the simulator's calling convention (state from the first inputs, then one
  ``step`` per time step) on inputs held constant, returning every step's outputs;
* ``params_for(cls, n, which, **values)``: every parameter at its default (or lower, upper, null),
  some overridden;
* ``inputs_for``: representative input arrays of a model in one of three scenarios: ``"typical"``
  operation, everything ``"shut"`` (positions and flows 0) or ``"open"`` (positions 1).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import pytest

from service.components.component import ComponentModel, SplicedEffect
from service.components.library import SignatureLibrary, load_model_class

#: Representative input values by port name, then by unit (simulator units).
_BY_NAME = {
    "supply_water_temperature": 65.0, "outdoor_air_temperature": 5.0, "return_air_temperature": 22.0,
    "inlet_air_temperature": 12.0, "setpoint": 21.0, "ambient_temperature": 15.0,
}
_BY_UNIT = {"degC": 18.0, "kg/s": 1.5, "m3/s": 1.2, "1": 0.4, "W": 1500.0, "": 19.0}
_SCENARIO_UNITS = {"shut": {"1": 0.0, "kg/s": 0.0, "m3/s": 0.0, "W": 0.0}, "open": {"1": 1.0}}


def library_model_classes() -> list[type[ComponentModel]]:
    """Every Python model class the signature library names, once, sorted by name."""
    classes = {load_model_class(s) for s in SignatureLibrary.load().values() if s.model}
    return sorted(classes, key=lambda c: (c.__module__, c.__name__))


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    for argument, wanted in (("component_class", ComponentModel), ("effect_class", SplicedEffect)):
        if argument in metafunc.fixturenames:
            classes = [c for c in library_model_classes() if issubclass(c, wanted)]
            metafunc.parametrize(argument, classes, ids=[c.__name__ for c in classes])


def _params_for(
    cls: type[ComponentModel], n: int = 1, which: str = "default", **values: float,
) -> dict[str, np.ndarray]:
    """Each parameter as an array of ``n`` equal values: its ``default``/``lower``/``upper``/``null``,
    overridden by ``values``."""
    unknown = set(values) - {p.name for p in cls.parameters}
    if unknown:
        raise KeyError(f"{cls.__name__} has no parameter(s) {sorted(unknown)}")
    return {p.name: np.full(n, float(values.get(p.name, getattr(p, which)))) for p in cls.parameters}


def _inputs_for(cls: type[ComponentModel], n: int = 1, scenario: str = "typical") -> dict[str, np.ndarray]:
    inputs = {}
    for port in cls.inputs:
        value = _SCENARIO_UNITS.get(scenario, {}).get(port.unit, _BY_NAME.get(port.name, _BY_UNIT.get(port.unit)))
        if value is None:
            raise KeyError(f"{cls.__name__}: no representative value for input {port.name!r} (unit {port.unit!r})")
        inputs[port.name] = np.full(n, value)
    return inputs


def _run_model(
    cls: type[ComponentModel], params: Mapping[str, np.ndarray], inputs: Mapping[str, np.ndarray],
    steps: int = 1, dt_s: float = 60.0,
) -> list[dict[str, np.ndarray]]:
    model = cls()
    state = model.initial_state(dict(params), dict(inputs), dt_s)
    return [{k: np.array(v, copy=True) for k, v in model.step(dict(params), dict(inputs), state, dt_s).items()}
            for _ in range(steps)]


@pytest.fixture
def run_model() -> Callable[..., list[dict[str, np.ndarray]]]:
    return _run_model


@pytest.fixture
def inputs_for() -> Callable[..., dict[str, np.ndarray]]:
    return _inputs_for


@pytest.fixture
def params_for() -> Callable[..., dict[str, np.ndarray]]:
    return _params_for
