"""FMU components: an FMI 2.0 co-simulation FMU behind the :class:`~service.components.component.ComponentModel` contract.

A signature says ``fmu = "file.fmu"`` instead of ``model = "module:Class"``; :func:`fmu_model_class`
builds a component class from the FMU's ``modelDescription.xml`` (``fmpy``): ``Real`` inputs and
outputs become ports with their units (:func:`check_port_units`), ``Real`` fixed or tunable
parameters become parameters bounded by ``[min, max]`` (invented as ``start ∓ |start|`` when
missing: placeholders, not priors). Each ensemble member has its own FMU instance for the whole run,
freed when the state is collected. Far slower than a vectorised Python model: prefer those for
calibration. Details and measured costs: ``docs/components.md``.
"""

from __future__ import annotations

import atexit
import ctypes
import pathlib
import shutil
import tempfile
import threading
import weakref
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar
from xml.etree import ElementTree

import numpy as np

from service.components.component import ComponentModel, Parameter, Params, Port, Signals, State
from service.errors import InputError, SignatureError, UnitError
from service.graph.units import UnitSpec, unit_spec
from service.matching.signature import QUANTITY_UNITS, Signature

__all__ = ["FMUComponent", "fmu_model_class", "live_instance_count", "check_port_units"]

_FMI_OK_OR_WARNING = 1  # fmi2Status above this is Discard / Error / Fatal / Pending


@dataclass(frozen=True)
class _FMUFile:
    """An FMU read and extracted: its identity, value references and the loaded library."""

    path: Path
    guid: str
    model_identifier: str
    unzip_dir: Path
    only_once_per_process: bool
    input_vrs: tuple[int, ...]
    output_vrs: tuple[int, ...]
    parameter_vrs: dict[str, int]
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]
    parameters: tuple[Parameter, ...]
    library: Any  # fmpy.fmi2.FMU2Slave: the shared library and its FMI function table


_CACHE: dict[tuple[str, int], type[FMUComponent]] = {}
_LOCK = threading.Lock()
_LIVE = [0]


def live_instance_count() -> int:
    """FMU instances currently alive (instantiated and not yet freed), over all FMU components."""
    return _LIVE[0]


def fmu_model_class(path: Path) -> type[FMUComponent]:
    """The component class for the FMI 2.0 co-simulation FMU at ``path``, cached per resolved path
    and modification time.

    :raises InputError: naming the file when it is missing, not an FMU (no ZIP archive, no
        ``modelDescription.xml``), not FMI 2.0, not co-simulation, or has no binary for this platform.
    """
    path = Path(path)
    try:
        resolved = path.resolve(strict=True)
        mtime = resolved.stat().st_mtime_ns
    except OSError:
        raise InputError(f"{path}: FMU file not found") from None
    key = (str(resolved), mtime)
    with _LOCK:
        cls = _CACHE.get(key)
        if cls is None:
            cls = _build_class(_open_fmu(resolved))
            _CACHE[key] = cls
    return cls


def _open_fmu(path: Path) -> _FMUFile:
    import fmpy
    from fmpy.fmi2 import FMU2Slave

    try:
        with zipfile.ZipFile(path) as archive:
            if "modelDescription.xml" not in archive.namelist():
                raise InputError(f"{path}: not an FMU: the archive has no modelDescription.xml")
            root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    except zipfile.BadZipFile:
        raise InputError(f"{path}: not an FMU: not a ZIP archive") from None
    except ElementTree.ParseError as exc:
        raise InputError(f"{path}: modelDescription.xml is not well-formed XML: {exc}") from None
    version = root.get("fmiVersion")
    if version != "2.0":
        raise InputError(f"{path}: FMI version {version}; only FMI 2.0 co-simulation FMUs are supported")
    try:
        description = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises bare Exception
        raise InputError(f"{path}: cannot read modelDescription.xml: {exc}") from None
    cosim = description.coSimulation
    if cosim is None:
        raise InputError(
            f"{path}: not a co-simulation FMU (model exchange only); export it for co-simulation"
        )

    inputs, outputs, parameters, input_vrs, output_vrs, parameter_vrs = [], [], [], [], [], {}
    for variable in description.modelVariables:
        if variable.type != "Real":
            continue
        unit = variable.unit or getattr(variable.declaredType, "unit", None) or ""
        if variable.causality == "input":
            inputs.append(Port(variable.name, unit, variable.description or ""))
            input_vrs.append(variable.valueReference)
        elif variable.causality == "output":
            outputs.append(Port(variable.name, unit, variable.description or ""))
            output_vrs.append(variable.valueReference)
        elif variable.causality == "parameter" and variable.variability in ("fixed", "tunable"):
            parameters.append(_parameter(path, variable, unit))
            parameter_vrs[variable.name] = variable.valueReference

    unzip_dir = Path(tempfile.mkdtemp(prefix="graphtwin-fmu-"))
    atexit.register(shutil.rmtree, unzip_dir, True)
    fmpy.extract(str(path), unzipdir=str(unzip_dir))
    binary = unzip_dir / "binaries" / fmpy.platform / (cosim.modelIdentifier + fmpy.sharedLibraryExtension)
    if not binary.is_file():
        raise InputError(
            f"{path}: no binary for this platform ({fmpy.platform}): "
            f"binaries/{fmpy.platform}/{binary.name} is missing"
        )
    try:
        library = FMU2Slave(guid=description.guid, unzipDirectory=str(unzip_dir),
                            modelIdentifier=cosim.modelIdentifier)
    except Exception as exc:
        raise InputError(f"{path}: cannot load the FMU's binary {binary.name}: {exc}") from None
    return _FMUFile(
        path=path, guid=description.guid, model_identifier=cosim.modelIdentifier, unzip_dir=unzip_dir,
        only_once_per_process=bool(cosim.canBeInstantiatedOnlyOncePerProcess),
        input_vrs=tuple(input_vrs), output_vrs=tuple(output_vrs), parameter_vrs=parameter_vrs,
        inputs=tuple(inputs), outputs=tuple(outputs), parameters=tuple(parameters), library=library,
    )


def _parameter(path: Path, variable: Any, unit: str) -> Parameter:
    """A Parameter from an FMU variable; missing min/max → ``start ∓ |start|`` (``[0, 1]`` at 0)."""
    if variable.start is None:
        raise InputError(f"{path}: parameter {variable.name} has no start value")
    start = float(variable.start)
    low = variable.min if variable.min is not None else getattr(variable.declaredType, "min", None)
    high = variable.max if variable.max is not None else getattr(variable.declaredType, "max", None)
    lower = float(low) if low is not None else (start - abs(start) if start != 0.0 else 0.0)
    upper = float(high) if high is not None else (start + abs(start) if start != 0.0 else 1.0)
    invented = [name for name, given in (("min", low), ("max", high)) if given is None]
    description = variable.description or ""
    if invented:
        description = (description + "; " if description else "") + (
            f"bound(s) {'/'.join(invented)} not given by the FMU: placeholder start ∓ |start|"
        )
    try:
        return Parameter(variable.name, unit, start, lower, upper, description)
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None


def _build_class(spec: _FMUFile) -> type[FMUComponent]:
    name = "FMU_" + "".join(ch if ch.isalnum() else "_" for ch in spec.model_identifier)
    return type(name, (FMUComponent,), {
        "__doc__": f"FMI 2.0 co-simulation FMU {spec.path.name} (model {spec.model_identifier}).",
        "__module__": __name__,
        "inputs": spec.inputs, "outputs": spec.outputs, "parameters": spec.parameters, "fmu": spec,
    })


class _Instances:
    """The FMU instances of one ensemble, their I/O buffers and the communication time.

    Lives in the state dict; ``weakref.finalize`` frees the instances when it is collected.
    """

    def __init__(self, spec: _FMUFile, n_ensemble: int):
        functions = spec.library._functions
        self.set_real = functions["fmi2SetReal"]
        self.get_real = functions["fmi2GetReal"]
        self.do_step = functions["fmi2DoStep"]
        self.time = 0.0
        n_in, n_out = len(spec.input_vrs), len(spec.output_vrs)
        self.n_in, self.n_out = n_in, n_out
        self.input_vrs = (ctypes.c_uint * max(n_in, 1))(*spec.input_vrs)
        self.output_vrs = (ctypes.c_uint * max(n_out, 1))(*spec.output_vrs)
        self.inputs = np.zeros((n_ensemble, max(n_in, 1)))
        self.outputs = np.zeros((n_ensemble, max(n_out, 1)))
        double_p = ctypes.POINTER(ctypes.c_double)
        self.input_rows = [self.inputs[i].ctypes.data_as(double_p) for i in range(n_ensemble)]
        self.output_rows = [self.outputs[i].ctypes.data_as(double_p) for i in range(n_ensemble)]
        self.components: list[int] = []
        self._finalizer = weakref.finalize(self, _free_instances, spec.library, self.components)

    def members(self):
        return zip(self.components, self.input_rows, self.output_rows)


def _free_instances(library: Any, components: list[int]) -> None:
    terminate = library._functions["fmi2Terminate"]
    free = library._functions["fmi2FreeInstance"]
    while components:
        component = components.pop()
        terminate(component)  # a status, never an exception: free regardless
        free(component)
        _LIVE[0] -= 1


def _check(status: int, what: str, spec: _FMUFile) -> None:
    if status > _FMI_OK_OR_WARNING:
        raise RuntimeError(f"{spec.path.name}: {what} returned fmi2Status {status}")


class FMUComponent(ComponentModel):
    """Base of the classes :func:`fmu_model_class` builds; ``fmu`` describes the FMU file.

    State: ``{"fmu": <instances>}`` — one FMU instance per ensemble member (module docstring).
    """

    fmu: ClassVar[_FMUFile]
    vectorised: ClassVar[bool] = False

    def __reduce__(self):
        return (_instance_for, (str(self.fmu.path),))

    def initial_state(self, params: Params, inputs: Signals, dt_s: float) -> State:
        """Instantiate one FMU per member, set parameters, then the first inputs, and initialise."""
        spec = self.fmu
        n_ens = _ensemble_size(params, inputs)
        if n_ens > 1 and spec.only_once_per_process:
            raise InputError(
                f"{spec.path}: the FMU can be instantiated only once per process, so it cannot run "
                f"an ensemble of {n_ens}"
            )
        library = spec.library
        functions = library._functions
        instantiate = functions["fmi2Instantiate"]
        holder = _Instances(spec, n_ens)
        names = [p.name for p in self.parameters if p.name in params]
        p_vrs = (ctypes.c_uint * max(len(names), 1))(*(spec.parameter_vrs[n] for n in names))
        p_values = np.column_stack([np.broadcast_to(np.asarray(params[n], float), (n_ens,)) for n in names]) \
            if names else np.zeros((n_ens, 1))
        p_values = np.ascontiguousarray(p_values)
        self._load_inputs(holder, inputs)
        resources = pathlib.Path(spec.unzip_dir, "resources").as_uri().encode()
        from fmpy.fmi2 import defaultCallbacks, fmi2CoSimulation, fmi2False

        double_p = ctypes.POINTER(ctypes.c_double)
        for i in range(n_ens):
            component = instantiate(f"{spec.model_identifier}_{i}".encode(), fmi2CoSimulation,
                                    spec.guid.encode(), resources, ctypes.byref(defaultCallbacks),
                                    fmi2False, fmi2False)
            if not component:
                raise RuntimeError(f"{spec.path.name}: fmi2Instantiate failed for ensemble member {i}")
            holder.components.append(component)
            _LIVE[0] += 1
            _check(functions["fmi2SetupExperiment"](component, fmi2False, 0.0, 0.0, fmi2False, 0.0),
                   "fmi2SetupExperiment", spec)
            if names:
                _check(functions["fmi2SetReal"](component, p_vrs, len(names), p_values[i].ctypes.data_as(double_p)),
                       "fmi2SetReal (parameters)", spec)
            _check(functions["fmi2EnterInitializationMode"](component), "fmi2EnterInitializationMode", spec)
            if holder.n_in:
                _check(holder.set_real(component, holder.input_vrs, holder.n_in, holder.input_rows[i]),
                       "fmi2SetReal (inputs)", spec)
            _check(functions["fmi2ExitInitializationMode"](component), "fmi2ExitInitializationMode", spec)
        return {"fmu": holder}

    def _load_inputs(self, holder: _Instances, inputs: Signals) -> None:
        buffer = holder.inputs
        for j, port in enumerate(self.inputs):
            buffer[:, j] = inputs[port.name]

    def step(self, params: Params, inputs: Signals, state: State, dt_s: float) -> Signals:
        """Set inputs at ``t_k``, read outputs at ``t_k``, ``fmi2DoStep(t_k, Δt)`` for every member."""
        holder: _Instances = state["fmu"]
        self._load_inputs(holder, inputs)
        set_real, get_real, do_step = holder.set_real, holder.get_real, holder.do_step
        n_in, n_out, in_vrs, out_vrs = holder.n_in, holder.n_out, holder.input_vrs, holder.output_vrs
        t = holder.time
        for component, in_row, out_row in holder.members():
            if (set_real(component, in_vrs, n_in, in_row) > 1 or get_real(component, out_vrs, n_out, out_row) > 1
                    or do_step(component, t, dt_s, 1) > 1):
                raise RuntimeError(
                    f"{self.fmu.path.name}: FMI call failed at t = {t} s (member {holder.components.index(component)})"
                )
        holder.time = t + dt_s
        out = holder.outputs
        return {port.name: out[:, j].copy() for j, port in enumerate(self.outputs)}


def _ensemble_size(params: Params, inputs: Signals) -> int:
    return max((int(np.size(v)) for v in (*params.values(), *inputs.values())), default=1)


def _instance_for(path: str) -> FMUComponent:
    return fmu_model_class(Path(path))()


def check_port_units(signature: Signature, model_class: type[ComponentModel]) -> None:
    """Every port of an FMU class that ``signature`` maps declares the unit the simulator passes for
    the mapping's quantity (:data:`~service.matching.signature.QUANTITY_UNITS`), or no unit.

    :raises SignatureError: naming the signature file, the port, the FMU's unit and the expected one.
    """
    declared = {port.name: port.unit for port in (*model_class.inputs, *model_class.outputs)}
    for side, mappings in (("inputs", signature.inputs), ("outputs", signature.outputs)):
        for mapping in mappings:
            unit, expected = declared[mapping.port], QUANTITY_UNITS[mapping.quantity]
            try:
                same = not unit or _conversion(unit_spec(unit)) == _conversion(unit_spec(expected))
            except UnitError:
                same = False
            if not same:
                raise SignatureError(
                    f"{signature.source_file or '<signature>'}: {side}.{mapping.port}: {signature.fmu} declares "
                    f"{mapping.port!r} in {unit!r}, the simulator passes {mapping.quantity} in {expected!r}: the FMU "
                    f"would read the values unconverted (declare the variable in {expected!r}, or wrap the FMU)")


def _conversion(spec: UnitSpec) -> tuple:
    """What makes two unit specs the same unit (their label aside)."""
    return spec.dimension, spec.multiplier, spec.offset, spec.difference
