"""The contract of ``service.components.component`` that every model of the library keeps (components and effects)."""

import importlib
import itertools

import numpy as np
import pytest

from service.components.component import ComponentModel, Parameter, Port, SplicedEffect


def _read_only(arrays):
    frozen = {}
    for name, value in arrays.items():
        value = np.array(value, dtype=float)
        value.flags.writeable = False
        frozen[name] = value
    return frozen


def test_declarations_are_valid(component_class):
    cls = component_class
    assert issubclass(cls, ComponentModel)
    assert cls.__name__ in importlib.import_module(cls.__module__).__all__
    for group in (cls.inputs, cls.outputs, cls.parameters):
        names = [item.name for item in group]
        assert len(names) == len(set(names)), f"{cls.__name__}: duplicate names in {names}"
        assert all(name.isidentifier() for name in names)
    assert all(isinstance(p, Port) for p in cls.inputs + cls.outputs)
    assert all(isinstance(p, Parameter) and p.unit for p in cls.parameters)
    assert all(isinstance(s, str) and s.isidentifier() and not s.startswith("_") for s in cls.states)
    assert sum(p.feedback for p in cls.inputs) <= 1
    if issubclass(cls, SplicedEffect):
        assert (cls.inputs[0].name, cls.outputs[0].name) == ("value_in", "value_out")


def test_defaults_and_nulls_lie_inside_bounds(component_class):
    for p in component_class.parameters:
        assert np.isfinite([p.lower, p.default, p.upper]).all()
        assert p.lower < p.upper and p.lower <= p.default <= p.upper, p
        if p.null is not None:
            assert p.lower <= p.null <= p.upper, p


def test_ensemble_step_equals_member_by_member_steps(component_class, inputs_for, run_model):
    cls, n = component_class, 6
    rng = np.random.default_rng(0)
    params = {p.name: p.lower + rng.random(n) * (p.upper - p.lower) for p in cls.parameters}
    inputs = {k: v * (0.8 + 0.4 * rng.random(n)) for k, v in inputs_for(cls, n).items()}
    together = run_model(cls, params, inputs, steps=12, dt_s=120.0)
    for i in range(n):
        alone = run_model(cls, {k: v[i:i + 1] for k, v in params.items()},
                          {k: v[i:i + 1] for k, v in inputs.items()}, steps=12, dt_s=120.0)
        for k in range(12):
            for port, value in together[k].items():
                assert value[i] == pytest.approx(alone[k][port][0], rel=1e-12, abs=1e-12), (port, k, i)


@pytest.mark.parametrize("scenario", ["typical", "shut", "open"])
@pytest.mark.parametrize("dt_s", [60.0, 900.0])
def test_outputs_are_finite_at_every_corner_of_the_prior_box(component_class, inputs_for, run_model, scenario, dt_s):
    """All 2^k corners at once, as one ensemble (k ≤ 9 parameters: at most 512 members)."""
    cls = component_class
    corners = np.array(list(itertools.product(*[(p.lower, p.upper) for p in cls.parameters])), dtype=float)
    n = len(corners)  # one member (an empty corner) for a model without parameters
    params = {p.name: corners[:, j].copy() for j, p in enumerate(cls.parameters)}
    for k, outputs in enumerate(run_model(cls, params, inputs_for(cls, n, scenario), steps=30, dt_s=dt_s)):
        assert set(outputs) == set(cls.output_names())
        for port, value in outputs.items():
            assert value.shape == (n,), (port, value.shape)
            assert np.isfinite(value).all(), f"{cls.__name__}.{port} at step {k}: {value[~np.isfinite(value)][:3]}"


def test_step_reads_inputs_and_parameters_without_writing_them(component_class, inputs_for):
    """The simulator hands boundary series as read-only views: a model must never write an input."""
    cls = component_class
    params = _read_only({p.name: np.full(3, p.default) for p in cls.parameters})
    inputs = _read_only(inputs_for(cls, 3))
    model = cls()
    state = model.initial_state(params, inputs, 60.0)
    for _ in range(3):
        model.step(params, inputs, state, 60.0)


def test_state_holds_the_declared_states_plus_precomputed_names(component_class, inputs_for):
    cls = component_class
    params = {p.name: np.full(2, p.default) for p in cls.parameters}
    state = cls().initial_state(params, inputs_for(cls, 2), 60.0)
    assert {k for k in state if not k.startswith("_")} == set(cls.states)
    assert all(np.shape(v)[:1] == (2,) for v in state.values())  # members first (a chain of tanks: (2, N))


def test_reported_outputs_are_not_changed_by_later_steps(component_class, inputs_for):
    """The simulator keeps a step's outputs to serve delayed (feedback) inputs one step later."""
    cls = component_class
    params = {p.name: np.full(2, p.default) for p in cls.parameters}
    inputs = inputs_for(cls, 2)
    model = cls()
    state = model.initial_state(params, inputs, 60.0)
    first = model.step(params, inputs, state, 60.0)
    kept = {k: v.copy() for k, v in first.items()}
    changed = {k: v * 0.5 + 1.0 for k, v in inputs.items()}
    for _ in range(3):
        model.step(params, changed, state, 60.0)
    for port in kept:
        np.testing.assert_array_equal(first[port], kept[port], err_msg=port)


def test_effects_vanish_at_their_null(effect_class, inputs_for, run_model):
    cls = effect_class
    assert any(p.null is not None for p in cls.parameters), f"{cls.__name__} has no parameter with a null value"
    params = {p.name: np.array([p.null if p.null is not None else p.default]) for p in cls.parameters}
    inputs = inputs_for(cls)
    out = run_model(cls, params, inputs, steps=5)[-1]["value_out"][0]
    assert out == pytest.approx(inputs["value_in"][0], abs=1e-12)
