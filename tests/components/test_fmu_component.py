"""FMU components: a hand-written FMI 2.0 co-simulation FMU (tests/fixtures/fmu_src) compiled at test
time, read into a ComponentModel, checked against service.components.fan.Fan and run inside the Simulator."""

import gc
import pickle
import re
import subprocess
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy", reason="fmpy is needed to run FMU components")

from fan_lag_fmu import FAN_CURVE, SOURCE, compile_fan_lag, fan_lag_model, package_fmu  # noqa: E402

from service.components.component import first_order_lag_factor  # noqa: E402
from service.components.fan import Fan  # noqa: E402
from service.components.fmu import fmu_model_class, live_instance_count  # noqa: E402
from service.components.library import load_model_class  # noqa: E402
from service.matching.signature import SignatureError, signature_from_dict  # noqa: E402
from service.model.assembled_model import ComponentInstance, Connection, ParameterRef  # noqa: E402
from service.model.simulator import Simulator  # noqa: E402

FAN_PARAMETERS = ("nominal_air_flow", "nominal_power", "c1", "c2", "c3", "c4")
FLOW = np.array([0.0, 0.4, 1.5, 1.5, -0.2, 0.9, 2.4, 1.1, 0.05, 1.5])  # m³/s: below 0, above nominal


@pytest.fixture(scope="session")
def build(tmp_path_factory):
    """Compile fan_lag.c against fmpy's FMI 2.0 headers; return (folder, binary, modelDescription)."""
    folder = tmp_path_factory.mktemp("fmu")
    try:
        binary = compile_fan_lag(folder)
    except FileNotFoundError as exc:
        pytest.skip(str(exc))
    except subprocess.CalledProcessError as exc:
        pytest.fail(f"the test FMU does not compile:\n{exc.stderr}")
    return folder, binary, (SOURCE / "modelDescription.xml").read_text(encoding="utf-8")


@pytest.fixture(scope="session")
def fan_lag_fmu(build) -> Path:
    folder, binary, description = build
    return package_fmu(folder, "FanLag.fmu", description, binary)


def _fan_params(nominal_power):
    n = len(nominal_power)
    params = {p.name: np.full(n, p.default) for p in Fan.parameters}
    params["nominal_power"] = np.asarray(nominal_power, float)
    params["nominal_air_flow"] = np.array([1.5, 1.2, 2.0])[:n]
    return params


def test_model_description_is_valid(fan_lag_fmu):
    fmpy.read_model_description(str(fan_lag_fmu), validate=True, validate_model_structure=True)


def test_ports_and_parameters_come_from_the_model_description(fan_lag_fmu):
    cls = fmu_model_class(fan_lag_fmu)
    assert cls is fmu_model_class(fan_lag_fmu)  # cached
    assert [(p.name, p.unit) for p in cls.inputs] == [("air_volume_flow", "m3/s")]
    assert [(p.name, p.unit) for p in cls.outputs] == [("electric_power", "W"), ("lagged_power", "W")]
    assert [p.name for p in cls.parameters] == [*FAN_PARAMETERS, "time_constant"]
    for name in FAN_PARAMETERS:  # given min/max: the same prior as the Python Fan
        fmu_spec, py_spec = cls.parameter(name), Fan.parameter(name)
        assert (fmu_spec.unit, fmu_spec.default, fmu_spec.lower, fmu_spec.upper) == \
            (py_spec.unit, py_spec.default, py_spec.lower, py_spec.upper)
    tau = cls.parameter("time_constant")  # no min/max in the FMU: start ∓ |start|
    assert (tau.unit, tau.default, tau.lower, tau.upper) == ("s", 60.0, 0.0, 120.0)
    assert "placeholder" in tau.description
    instance = cls()
    assert type(pickle.loads(pickle.dumps(instance))) is cls


def test_power_matches_the_python_fan_and_the_lag_is_exact(fan_lag_fmu):
    model = fmu_model_class(fan_lag_fmu)()
    fan = Fan()
    params = _fan_params([900.0, 1800.0, 5000.0])
    tau = np.array([60.0, 300.0, 0.0])  # 0: no lag
    fmu_params = {**params, "time_constant": tau}
    dt = 60.0
    inputs = lambda v: {"air_volume_flow": np.full(3, v), "inlet_air_temperature": np.full(3, 20.0)}  # noqa: E731
    state = model.initial_state(fmu_params, inputs(FLOW[0]), dt)
    lag = fan.step(params, inputs(FLOW[0]), {}, dt)["electric_power"]  # starts in steady state
    share = first_order_lag_factor(dt, tau)
    for flow in FLOW:
        expected = fan.step(params, inputs(flow), {}, dt)["electric_power"]
        out = model.step(fmu_params, inputs(flow), state, dt)
        np.testing.assert_allclose(out["electric_power"], expected, rtol=1e-9, atol=0.0)
        np.testing.assert_allclose(out["lagged_power"], lag, rtol=1e-12, atol=0.0)
        lag = lag + share * (expected - lag)
    assert live_instance_count() >= 3
    del state
    gc.collect()
    assert live_instance_count() == 0


def test_runs_inside_the_simulator_beside_the_python_fan_without_leaking_instances(fan_lag_fmu, tmp_path):
    """flow sensor (boundary) → FMU fan → power meter (target) on lagged_power, and the same flow
    into service.components.fan.Fan in the same run: electric power equal within rtol 1e-9 (the same double
    arithmetic in C and numpy), lagged power the exact first-order lag of it."""
    # an absolute fmu path is kept as is, whether or not the signature has a file of its own
    model = fan_lag_model(fan_lag_fmu, tmp_path / "fan_fmu.toml")
    assert model.components["urn:fan"].signature.fmu == fan_lag_fmu.resolve()
    python_fan = signature_from_dict({"id": "Fan", "modeled_nodes": ["n"], "nodes": {"n": {"classes": ["urn:Fan"]}},
                                      "model": "service.components.fan:Fan"})
    model = replace(
        model,
        components={**model.components, "urn:pyfan": ComponentInstance(
            iri="urn:pyfan", signature=python_fan, bindings={"n": "urn:pyfan"}, modeled_nodes=("urn:pyfan",),
            mapped_parameters={})},
        connections=(*model.connections, Connection("urn:flow", "measured_value", "urn:pyfan", "air_volume_flow")),
        mapped_parameters=(
            *model.mapped_parameters,
            *(ParameterRef("urn:pyfan", Fan.parameter(name), value) for name, value in FAN_CURVE.items()),
            ParameterRef("urn:pyfan", Fan.parameter("impeller_heat_share"), 0.0)),
        estimated_parameters=(*model.estimated_parameters, ParameterRef("urn:pyfan", Fan.parameter("nominal_power"))),
    )
    theta = np.array([[900.0, 60.0, 900.0], [1800.0, 120.0, 1800.0], [5000.0, 30.0, 5000.0]])
    simulator = Simulator(model, 60.0)
    for _ in range(20):  # a calibration calls run again and again: instances must not pile up
        result = simulator.run({"urn:flow": FLOW}, theta)
    gc.collect()
    assert live_instance_count() == 0

    power = result.outputs[("urn:pyfan", "electric_power")]  # [member, step]
    assert np.array_equal(power[:, 4], power[:, 0]) and power.max() > 5000.0  # flow < 0 is 0; flow above nominal
    np.testing.assert_allclose(result.outputs[("urn:fan", "electric_power")], power, rtol=1e-9, atol=0.0)
    share = first_order_lag_factor(60.0, theta[:, 1])
    lag = np.empty_like(power)
    lag[:, 0] = power[:, 0]
    for k in range(1, FLOW.size):
        lag[:, k] = lag[:, k - 1] + share * (power[:, k - 1] - lag[:, k - 1])
    np.testing.assert_allclose(result.target("urn:meter"), lag, rtol=1e-9, atol=0.0)


def test_bad_files_raise_value_errors_naming_the_file(build, tmp_path):
    _, binary, description = build
    not_fmu = tmp_path / "no_description.fmu"
    with zipfile.ZipFile(not_fmu, "w") as archive:
        archive.writestr("readme.txt", "not an FMU")
    with pytest.raises(ValueError, match=r"no_description\.fmu.*modelDescription\.xml"):
        fmu_model_class(not_fmu)
    with pytest.raises(ValueError, match=r"missing\.fmu: FMU file not found"):
        fmu_model_class(tmp_path / "missing.fmu")
    text = tmp_path / "text.fmu"
    text.write_text("hello")
    with pytest.raises(ValueError, match=r"text\.fmu: not an FMU"):
        fmu_model_class(text)
    fmi3 = package_fmu(tmp_path, "fmi3.fmu", description.replace('fmiVersion="2.0"', 'fmiVersion="3.0"'), binary)
    with pytest.raises(ValueError, match=r"fmi3\.fmu: FMI version 3\.0"):
        fmu_model_class(fmi3)
    me_only = re.sub(r"<CoSimulation[^>]*/>", '<ModelExchange modelIdentifier="FanLag"/>', description)
    assert "CoSimulation" not in me_only
    me_fmu = package_fmu(tmp_path, "model_exchange.fmu", me_only, binary)
    with pytest.raises(ValueError, match=r"model_exchange\.fmu: not a co-simulation FMU"):
        fmu_model_class(me_fmu)
    no_binary = package_fmu(tmp_path, "no_binary.fmu", description, None)
    with pytest.raises(ValueError, match=r"no_binary\.fmu: no binary for this platform"):
        fmu_model_class(no_binary)


def test_an_fmu_signature_mapping_a_port_the_fmu_lacks_names_file_key_and_ports(fan_lag_fmu, tmp_path):
    signature = signature_from_dict({
        "id": "FanFMU", "modeled_nodes": ["n"], "nodes": {"n": {"classes": ["urn:Fan"]}},
        "fmu": str(Path(fan_lag_fmu).resolve()), "outputs": {"lagged_powr": {"node": "n", "quantity": "power"}},
    }, tmp_path / "fan_fmu.toml")
    with pytest.raises(SignatureError, match=r"fan_fmu\.toml: outputs\.lagged_powr: .* has no output port "
                                             r"'lagged_powr'; its output ports: .*lagged_power"):
        load_model_class(signature)


def test_an_fmu_input_the_signature_does_not_map_is_refused_not_run_on_nan(fan_lag_fmu, tmp_path):
    signature = signature_from_dict({"id": "FanFMU", "modeled_nodes": ["n"], "nodes": {"n": {"classes": ["urn:Fan"]}},
                                     "fmu": str(fan_lag_fmu.resolve())}, tmp_path / "fan_fmu.toml")
    with pytest.raises(SignatureError, match=r"fan_fmu.toml: inputs.air_volume_flow: .*FanLag.fmu has input port\(s\) "
                                             r"'air_volume_flow' the signature does not map"):
        load_model_class(signature)


@pytest.mark.parametrize("unit", ["m3/h", "furlong/s"])
def test_an_fmu_port_in_another_unit_than_the_simulator_passes_is_refused(build, tmp_path, unit):
    folder, binary, description = build
    flow_input = '<Real unit="m3/s" start="0"/></ScalarVariable>'
    assert description.count(flow_input) == 1
    fmu = package_fmu(tmp_path, "FanLagPerHour.fmu", description.replace(flow_input, flow_input.replace("m3/s", unit)), binary)
    with pytest.raises(SignatureError, match=rf"fan_fmu.toml: inputs.air_volume_flow: .*FanLagPerHour.fmu declares "
                                             rf"'air_volume_flow' in '{unit}', the simulator passes volume_flow in 'm3/s'"):
        fan_lag_model(fmu, tmp_path / "fan_fmu.toml")
