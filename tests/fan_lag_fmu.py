"""Build the test FMU ``FanLag`` (FMI 2.0 co-simulation) from its C source in ``tests/fixtures/fmu_src``.

Used by ``tests/components/test_fmu_component.py`` and ``tests/bench/bench_simulator.py``; nothing is committed
as a binary (``*.fmu`` is gitignored): the FMU is compiled into a temporary folder at test time with
``gcc`` against the FMI 2.0 headers fmpy ships in ``fmpy/c-code``.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy

from service.components.library import load_model_class
from service.matching.signature import signature_from_dict
from service.model.assembled_model import AssembledModel, ComponentInstance, Connection, MeasurementLink, ParameterRef

__all__ = ["SOURCE", "MODEL_IDENTIFIER", "compile_fan_lag", "package_fmu", "build_fan_lag_fmu", "fan_lag_model",
           "FAN_CURVE"]

SOURCE = Path(__file__).parent / "fixtures" / "fmu_src"
MODEL_IDENTIFIER = "FanLag"
#: Mapped parameters of :func:`fan_lag_model`: nominal flow (m³/s) and the ASHRAE curve c1..c4.
FAN_CURVE = {"nominal_air_flow": 1.5, "c1": 0.0013, "c2": 0.147, "c3": 0.9506, "c4": -0.0998}


def compile_fan_lag(folder: Path) -> Path:
    """Compile ``fan_lag.c`` into ``folder``; returns the shared library.

    :raises FileNotFoundError: no ``gcc`` on the PATH.
    :raises subprocess.CalledProcessError: the compiler failed (its stderr is attached).
    """
    gcc = shutil.which("gcc")
    if gcc is None:
        raise FileNotFoundError("gcc is not installed: cannot compile the test FMU")
    binary = Path(folder) / f"{MODEL_IDENTIFIER}{fmpy.sharedLibraryExtension}"
    headers = Path(fmpy.__file__).parent / "c-code"
    subprocess.run([gcc, "-shared", "-fPIC", "-O2", f"-I{headers}", str(SOURCE / "fan_lag.c"), "-o", str(binary), "-lm"],
                   check=True, capture_output=True, text=True)
    return binary


def package_fmu(folder: Path, name: str, model_description: str, binary: Path | None) -> Path:
    """Zip ``model_description`` (and ``binary`` for this platform, unless None) into ``folder/name``."""
    fmu = Path(folder) / name
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", model_description)
        if binary is not None:
            archive.write(binary, f"binaries/{fmpy.platform}/{MODEL_IDENTIFIER}{fmpy.sharedLibraryExtension}")
    return fmu


def build_fan_lag_fmu(folder: Path) -> Path:
    """Compile and package ``FanLag.fmu`` in ``folder`` (errors as :func:`compile_fan_lag`)."""
    binary = compile_fan_lag(folder)
    description = (SOURCE / "modelDescription.xml").read_text(encoding="utf-8")
    return package_fmu(folder, f"{MODEL_IDENTIFIER}.fmu", description, binary)


def _instance(iri: str, signature, measured: bool = False) -> ComponentInstance:
    return ComponentInstance(iri=iri, signature=signature, bindings={"n": iri}, modeled_nodes=(iri,), mapped_parameters={},
                             measurement=MeasurementLink(iri, None, None) if measured else None)


def fan_lag_model(fmu: Path, signature_file: Path | None = None) -> AssembledModel:
    """flow sensor ``urn:flow`` (boundary) → FMU fan ``urn:fan`` → power meter ``urn:meter`` (target,
    on ``lagged_power``); :data:`FAN_CURVE` mapped, θ = (nominal_power [W], time_constant [s])."""
    device = signature_from_dict({"id": "Device", "modeled_nodes": ["n"], "nodes": {"n": {"classes": ["urn:Device"]}},
                                  "model": "service.components.measuring_device:MeasuringDevice"})
    fan = signature_from_dict({"id": "FanFMU", "modeled_nodes": ["n"],
                               "nodes": {"n": {"classes": ["urn:Fan"]}, "flow": {"classes": ["urn:Device"]}},
                               "inputs": {"air_volume_flow": {"source": "flow", "quantity": "volume_flow"}},
                               "fmu": str(Path(fmu).resolve())}, signature_file)
    cls = load_model_class(fan)
    components = {
        "urn:flow": _instance("urn:flow", device, True),
        "urn:fan": _instance("urn:fan", fan),
        "urn:meter": _instance("urn:meter", device, True),
    }
    connections = (
        Connection("urn:flow", "measured_value", "urn:fan", "air_volume_flow"),
        Connection("urn:fan", "lagged_power", "urn:meter", "measured_value"),
    )
    mapped = tuple(ParameterRef("urn:fan", cls.parameter(name), value) for name, value in FAN_CURVE.items())
    estimated = (ParameterRef("urn:fan", cls.parameter("nominal_power")), ParameterRef("urn:fan", cls.parameter("time_constant")))
    return AssembledModel(components=components, connections=connections, boundary_inputs=("urn:flow",),
                          targets=("urn:meter",), mapped_parameters=mapped, estimated_parameters=estimated)
