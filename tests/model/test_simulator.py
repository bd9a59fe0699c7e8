"""The ensemble simulator: order, the one-step delay that breaks a loop, boundary series, sub-steps."""

import dataclasses
import warnings

import numpy as np
import pytest

from service.components.component import ComponentModel, Parameter, Port
from service.matching.signature import signature_from_dict
from service.model.assembled_model import AssembledModel, ComponentInstance, Connection, MeasurementLink, ParameterRef
from service.model.simulator import Simulator, component_order, simulate, target_series, warmup_index


class Gain(ComponentModel):
    """y = k·x."""

    inputs = (Port("x", "1"),)
    outputs = (Port("y", "1"),)
    parameters = (Parameter("k", "1", 1.0, 0.0, 10.0),)

    def step(self, params, inputs, state, dt_s):
        return {"y": params["k"] * inputs["x"]}


class Summer(ComponentModel):
    """y = a + b, with b a feedback input."""

    inputs = (Port("a", "1"), Port("b", "1", feedback=True))
    outputs = (Port("y", "1"),)

    def step(self, params, inputs, state, dt_s):
        return {"y": inputs["a"] + inputs["b"]}


class Plain(Summer):
    inputs = (Port("a", "1"), Port("b", "1"))


class FlowSetter(ComponentModel):
    """m = x (a flow set by a command)."""

    inputs = (Port("x", "1"),)
    outputs = (Port("m", "kg/s"),)

    def step(self, params, inputs, state, dt_s):
        return {"m": inputs["x"]}


def _instance(iri, cls, measured=False):
    signature = signature_from_dict({"id": iri.split(":")[-1].capitalize(), "modeled_nodes": ["n"], "nodes": {"n": {"classes": ["urn:C"]}},
                                     "model": f"{cls.__module__}:{cls.__name__}"})
    return ComponentInstance(iri=iri, signature=signature, bindings={"n": iri}, modeled_nodes=(iri,), mapped_parameters={},
                             measurement=MeasurementLink(iri, None, None) if measured else None)


def _loop_model(summer=Summer):
    """source (boundary) → sum → gain → back into sum.b: y_k = u_k + k·y_{k−1}."""
    import sys
    module = sys.modules[__name__]
    module.Summer, module.Plain = Summer, Plain
    components = {
        "urn:source": _instance("urn:source", __import__("service.components.measuring_device", fromlist=["x"]).MeasuringDevice, True),
        "urn:sum": _instance("urn:sum", summer),
        "urn:gain": _instance("urn:gain", Gain),
    }
    connections = (
        Connection("urn:source", "measured_value", "urn:sum", "a"),
        Connection("urn:sum", "y", "urn:gain", "x"),
        Connection("urn:gain", "y", "urn:sum", "b"),
    )
    return AssembledModel(components=components, connections=connections, boundary_inputs=("urn:source",), targets=(),
                          mapped_parameters=(), estimated_parameters=(ParameterRef("urn:gain", Gain.parameters[0]),))


def test_feedback_port_closes_the_loop_one_step_late():
    model = _loop_model()
    order, delayed, notes = component_order(model)
    assert order.index("urn:sum") < order.index("urn:gain") and not notes
    assert [c.target_port for c in delayed] == ["b"]
    u = np.array([1.0, 0.0, 0.0, 0.0, 0.0])
    y = Simulator(model, 60.0).run({"urn:source": u}, np.array([[0.5], [2.0]]), record=[("urn:sum", "y")]).outputs[("urn:sum", "y")]
    # y_0 = u_0 + 0 (no measured value for the gain at t = 0), then y_k = u_k + k·y_{k−1}
    assert y[0] == pytest.approx([1.0, 0.5, 0.25, 0.125, 0.0625])
    assert y[1] == pytest.approx([1.0, 2.0, 4.0, 8.0, 16.0])


def test_a_cycle_without_feedback_port_is_broken_with_a_note():
    model = _loop_model(Plain)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a note to report, not a Python warning on the terminal
        simulator = Simulator(model, 60.0)
    assert any("they form a loop with no feedback port, broken there" in note for note in simulator.notes)


def test_ensemble_is_member_by_member_and_boundary_gaps_are_held():
    model = _loop_model()
    u = np.array([1.0, np.nan, np.nan, 2.0])
    sim = Simulator(model, 60.0)
    theta = np.array([[0.1], [0.7]])
    together = sim.run({"urn:source": u}, theta).outputs[("urn:sum", "y")]
    for i in range(2):
        alone = sim.run({"urn:source": u}, theta[i:i + 1]).outputs[("urn:sum", "y")][0]
        assert together[i] == pytest.approx(alone)
    assert np.isfinite(together).all()


def test_missing_boundary_series_and_bad_theta_are_named():
    sim = Simulator(_loop_model(), 60.0)
    with pytest.raises(ValueError, match="urn:source"):
        sim.run({}, np.array([[1.0]]))
    with pytest.raises(ValueError, match="columns"):
        sim.run({"urn:source": np.zeros(3)}, np.array([[1.0, 2.0]]))


def test_substeps_report_at_data_steps():
    model = _loop_model()
    coarse = Simulator(model, 60.0, substeps=1).run({"urn:source": np.ones(4)}, np.array([[0.0]]))
    fine = Simulator(model, 60.0, substeps=3).run({"urn:source": np.ones(4)}, np.array([[0.0]]))
    assert fine.outputs[("urn:sum", "y")].shape == (1, 4)
    assert fine.outputs[("urn:sum", "y")] == pytest.approx(coarse.outputs[("urn:sum", "y")])


def test_between_data_steps_a_schedule_is_held_and_a_sensor_interpolated():
    """A boundary device that holds values (a setpoint schedule) steps at its sample; a sensor's
    series ramps between samples. Seen through a first-order lag, the hold starts responding only at
    the step's sample, the interpolation a whole data step earlier."""
    from service.components.effects.first_order_lag import FirstOrderLag

    def lagged(holds: bool) -> np.ndarray:
        source = _instance("urn:source", __import__("service.components.measuring_device", fromlist=["x"]).MeasuringDevice, True)
        source = dataclasses.replace(source, signature=dataclasses.replace(source.signature, steps=holds))
        model = AssembledModel(components={"urn:source": source, "urn:lag": _instance("urn:lag", FirstOrderLag)},
                               connections=(Connection("urn:source", "measured_value", "urn:lag", "value_in"),),
                               boundary_inputs=("urn:source",), targets=(), mapped_parameters=(),
                               estimated_parameters=tuple(ParameterRef("urn:lag", p) for p in FirstOrderLag.parameters))
        run = Simulator(model, 600.0, substeps=10).run({"urn:source": np.array([0.0, 0.0, 1.0, 1.0])}, np.array([[300.0]]))
        return run.outputs[("urn:lag", "value_out")][0]

    held, ramped = lagged(True), lagged(False)
    # the hold: nothing before the sample at 1,200 s, then one 60-s sub-step of the lag at the sample
    assert held[:2] == pytest.approx([0.0, 0.0]) and held[2] == pytest.approx(-np.expm1(-60.0 / 300.0))
    assert ramped[1] == pytest.approx(0.0) and ramped[2] > held[2] + 0.3


def _sensor_loop_model():
    """source (boundary) → sum → gain → sensor (target) → back into sum.b (feedback)."""
    from service.components.measuring_device import MeasuringDevice

    base = _loop_model()
    components = {**base.components, "urn:sensor": _instance("urn:sensor", MeasuringDevice, True)}
    connections = (
        Connection("urn:source", "measured_value", "urn:sum", "a"),
        Connection("urn:sum", "y", "urn:gain", "x"),
        Connection("urn:gain", "y", "urn:sensor", "measured_value"),
        Connection("urn:sensor", "measured_value", "urn:sum", "b"),
    )
    return AssembledModel(components=components, connections=connections, boundary_inputs=("urn:source",),
                          targets=("urn:sensor",), mapped_parameters=(), estimated_parameters=base.estimated_parameters)


def test_a_delayed_sensor_starts_from_its_first_reading():
    """At t = 0 the loop-closing input gets the sensor's measured value when the run has its series,
    else 0; afterwards the sensor's simulated value of the step before: y_k = u_k + k·y_{k−1}."""
    model = _sensor_loop_model()
    _, delayed, _ = component_order(model)
    assert [(c.source, c.target_port) for c in delayed] == [("urn:sensor", "b")]
    u = np.array([1.0, 0.0, 0.0])
    sim = Simulator(model, 60.0)
    theta = np.array([[0.5]])
    seeded = sim.run({"urn:source": u, "urn:sensor": np.array([10.0, np.nan, np.nan])}, theta)
    assert seeded.outputs[("urn:sum", "y")][0] == pytest.approx([11.0, 5.5, 2.75])
    assert target_series(model, seeded) == {"urn:sensor": pytest.approx([5.5, 2.75, 1.375])}
    unseeded = sim.run({"urn:source": u}, theta)
    assert unseeded.outputs[("urn:sum", "y")][0] == pytest.approx([1.0, 0.5, 0.25])


@pytest.mark.parametrize("substeps", [1, 3])
def test_a_warm_up_is_simulated_and_left_out_of_the_result(substeps):
    """Every output (stepped, and memoryless ones evaluated at once before and after the stepping)
    of a run with ``warmup_steps = k`` is the full run's from step k on."""
    model = _sensor_loop_model()
    u = np.array([1.0, 3.0, 0.0, 2.0, 0.5, 4.0])
    boundary = {"urn:source": u, "urn:sensor": np.full(6, 10.0)}
    sim = Simulator(model, 60.0, substeps)
    theta = np.array([[0.5], [0.9]])
    full = sim.run(boundary, theta)
    warmed = sim.run(boundary, theta, warmup_steps=4)
    assert set(warmed.outputs) == set(full.outputs)
    for key, values in full.outputs.items():
        assert warmed.outputs[key].shape == (2, 2)
        assert warmed.outputs[key] == pytest.approx(values[:, 4:]), key
    with pytest.raises(ValueError, match="warm-up of 6 steps leaves nothing of 6"):
        sim.run(boundary, theta, warmup_steps=6)


def test_warm_up_index_takes_the_steps_before_and_repeats_the_first_period_before_the_data():
    assert warmup_index(slice(5, 8), 3).tolist() == [2, 3, 4, 5, 6, 7]
    assert warmup_index(slice(1, 3), 5, period_steps=4).tolist() == [0, 1, 2, 3, 0, 1, 2]
    assert warmup_index(slice(0, 2), 3).tolist() == [0, 0, 0, 0, 1]


def test_fixed_values_override_theta_columns():
    model = _loop_model()
    u = np.array([1.0, 0.0, 0.0])
    fixed = simulate(model, {"urn:source": u}, np.array([[2.0], [3.0]]), step_s=60.0, fixed={"urn:gain#k": 0.5})
    assert fixed.outputs[("urn:sum", "y")] == pytest.approx(np.array([[1.0, 0.5, 0.25]] * 2))
    assert fixed.step_s == 60.0


def test_a_cycle_without_feedback_port_is_broken_at_a_flow():
    """urn:a (FlowSetter) → urn:b.a, urn:b (Plain) → urn:a.x: IRI order alone would delay the
    connection into urn:a; the flow rule delays the kg/s connection into urn:b instead."""
    components = {"urn:a": _instance("urn:a", FlowSetter), "urn:b": _instance("urn:b", Plain)}
    connections = (Connection("urn:a", "m", "urn:b", "a"), Connection("urn:b", "y", "urn:a", "x"))
    model = AssembledModel(components=components, connections=connections, boundary_inputs=(), targets=(),
                           mapped_parameters=(), estimated_parameters=())
    order, delayed, notes = component_order(model)
    assert delayed == {connections[0]} and order == ["urn:b", "urn:a"]
    assert notes == ["urn:b reads urn:a's m one step late (as a): they form a loop with no feedback port, broken there"]


class Lag(ComponentModel):
    """First-order lag y_{k+1} = y_k + (1 − e^{−Δt/τ})(x_k − y_k), τ = 120 s: a state, so stepped."""

    inputs = (Port("x", "1"),)
    outputs = (Port("y", "1"),)
    states = ("y",)

    def initial_state(self, params, inputs, dt_s):
        return {"y": np.array(inputs["x"], dtype=float)}

    def step(self, params, inputs, state, dt_s):
        state["y"] = state["y"] + -np.expm1(-dt_s / 120.0) * (inputs["x"] - state["y"])
        return {"y": state["y"].copy()}


def test_memoryless_ends_are_evaluated_at_once_and_agree_with_stepping():
    """source → pre-gain (memoryless, fed by the boundary: evaluated over all steps at once) → a
    feedback loop and a lag (stepped) → two sensors (memoryless, feeding nothing: evaluated at the
    data steps only); the outputs are those of stepping every component."""
    import sys

    from service.components.measuring_device import MeasuringDevice

    sys.modules[__name__].Lag = Lag
    base = _loop_model()
    components = {**base.components, "urn:pre": _instance("urn:pre", Gain), "urn:lag": _instance("urn:lag", Lag),
                  "urn:out": _instance("urn:out", MeasuringDevice, True),
                  "urn:out2": _instance("urn:out2", MeasuringDevice, True)}
    connections = (
        Connection("urn:source", "measured_value", "urn:pre", "x"),
        Connection("urn:pre", "y", "urn:sum", "a"),
        Connection("urn:sum", "y", "urn:gain", "x"),
        Connection("urn:gain", "y", "urn:sum", "b"),
        Connection("urn:gain", "y", "urn:out", "measured_value"),
        Connection("urn:pre", "y", "urn:lag", "x"),
        Connection("urn:lag", "y", "urn:out2", "measured_value"),
    )
    model = AssembledModel(components=components, connections=connections, boundary_inputs=("urn:source",),
                           targets=("urn:out", "urn:out2"), mapped_parameters=(),
                           estimated_parameters=(ParameterRef("urn:pre", Gain.parameters[0]),
                                                 ParameterRef("urn:gain", Gain.parameters[0])))
    sim = Simulator(model, 60.0, substeps=3)
    assert sim.ahead == ["urn:pre", "urn:source"] or sim.ahead == ["urn:source", "urn:pre"]
    assert sorted(sim.behind) == ["urn:out", "urn:out2"]
    u = np.sin(np.arange(12) / 2.0)
    theta = np.array([[2.0, 0.5], [1.0, -0.3], [0.5, 0.9]])
    at_once = sim.run({"urn:source": u}, theta)
    sim.ahead, sim.behind = [], []
    stepped = sim.run({"urn:source": u}, theta)
    assert at_once.outputs.keys() == stepped.outputs.keys()
    for key in stepped.outputs:
        np.testing.assert_array_equal(at_once.outputs[key], stepped.outputs[key], err_msg=str(key))
    # the loop as stated: y_k = 2·u_k + 0.5·y_{k−1} on the sub-steps, reported every third one
    y, fine_u = 0.0, np.interp(np.arange(34) / 3.0, np.arange(12), u)
    expected = []
    for i, value in enumerate(fine_u):
        y = 2.0 * value + 0.5 * y
        if i % 3 == 0:
            expected.append(0.5 * y)
    assert at_once.target("urn:out")[0] == pytest.approx(expected)


def test_a_draw_through_unit_s_coils_see_the_fan_s_air_flow_from_step_0():
    """FLEXLAB draws its air through the coils: the fan's air flow reaches them a step late (the
    cycle is broken at that flow). With constant inputs, step 0 equals every later step (before,
    the coils saw no air at step 0 and the supply air read the heating water's 60 °C)."""
    from service.graph.store import GraphStore
    from service.model.assembly import assemble
    from service.resources import examples_dir

    store = GraphStore.embedded(None)
    store.load_model("flexlab", examples_dir() / "flexlab_ahu" / "model.ttl")
    model = assemble(store, "flexlab")
    simulator = Simulator(model, 60.0)
    assert {(c.source_port, c.target_port) for c in simulator.delayed} == {("outlet_air_mass_flow", "air_mass_flow")}
    boundary = {c: np.full(5, 0.5 if "command" in c else 15.0) for c in model.boundary_inputs}
    result = simulator.run(boundary, np.array([[r.spec.default for r in model.estimated_parameters]]))
    for (iri, port), values in result.outputs.items():
        np.testing.assert_allclose(values[0], values[0, -1], rtol=1e-12, err_msg=f"{iri} {port}")
