"""The contract every component model (and every effect) of the library fulfils.

A model steps a whole ensemble of parameter sets at once: every parameter, input, state and output
is a 1-D ``numpy`` array of length ``n_ensemble`` (one parameter set: ``n_ensemble == 1``). At step
``k`` the simulator calls ``outputs = model.step(params, inputs, state, dt_s)`` with inputs and state
at ``t_k``; the model returns its outputs at ``t_k`` and advances ``state`` to ``t_{k+1}``. First-order
lags use the exact discretisation ``x ← x + (1 − e^{−Δt/τ})·(x∞ − x)``. Units: SI, temperatures in °C
(``"degC"``), declared on every port and parameter. An effect (:class:`SplicedEffect`) maps what a
spliced port carries (``value_in``) to ``value_out``. Details: ``docs/components.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = [
    "Port", "Parameter", "ComponentModel", "SplicedEffect", "Params", "Signals", "State",
    "first_order_lag_factor", "bound_side", "AIR_SPECIFIC_HEAT_J_PER_KG_K", "WATER_SPECIFIC_HEAT_J_PER_KG_K",
    "AIR_DENSITY_KG_PER_M3", "WATER_DENSITY_KG_PER_M3", "DEFAULT_SETTLING_S", "MINIMUM_AIR_MASS_FLOW_KG_PER_S",
]

Params = dict[str, np.ndarray]
Signals = dict[str, np.ndarray]
State = dict[str, np.ndarray]

#: c_p of dry air near 20 °C, J/(kg·K).
AIR_SPECIFIC_HEAT_J_PER_KG_K = 1006.0
#: c_p of liquid water near 50 °C, J/(kg·K).
WATER_SPECIFIC_HEAT_J_PER_KG_K = 4181.0
#: Floor of the air mass flow in heat-to-temperature conversions, kg/s: keeps T finite with the fan off.
MINIMUM_AIR_MASS_FLOW_KG_PER_S = 0.1
#: Standard air (20 °C, 101.325 kPa), kg/m³: converts volumetric to mass air flow.
AIR_DENSITY_KG_PER_M3 = 1.204
#: Water near 50 °C, kg/m³.
WATER_DENSITY_KG_PER_M3 = 988.0


@dataclass(frozen=True)
class Port:
    """An input or output signal of a component model.

    ``feedback=True`` marks an input that closes a control loop (a controller's measured value):
    when the connections form a cycle, the simulator serves this input one step late. ``reports``
    names, on an output, the input it reports as received (a valve's position feedback reports its
    position input): an effect that leaves readings unchanged rewires such an output to the input's feed.
    ``fallback_parameter`` names, on an input, the parameter that stands in for it where the graph
    gives nothing to feed it (a coil's supply water temperature, measured or estimated): the
    parameter is estimated then, and left out where the input is fed.
    """

    name: str
    unit: str
    description: str = ""
    feedback: bool = False
    reports: str | None = None
    fallback_parameter: str | None = None


@dataclass(frozen=True)
class Parameter:
    """A model parameter with its unit, default and physical prior bounds ``[lower, upper]``.

    ``null`` is, for an effect, the value at which the effect vanishes (the base model);
    ``attainable`` the bounds that are states the physics reaches (a weight of 1: a valve entirely
    stuck; a position of 0 or 1: stuck shut or wide open), so that a fit there is the effect itself,
    not a size the prior cut short. ``drifts`` False for what construction fixes (a pipe's water
    content, a coil's heat capacity): the diagnosis tries no drift of it.
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    description: str = ""
    null: float | None = None
    attainable: tuple[float, ...] = ()
    drifts: bool = True

    def __post_init__(self) -> None:
        if not self.lower <= self.default <= self.upper:
            raise ValueError(
                f"parameter {self.name}: default {self.default} outside bounds [{self.lower}, {self.upper}]"
            )
        if not set(self.attainable) <= {self.lower, self.upper}:
            raise ValueError(f"parameter {self.name}: attainable {self.attainable} are not its bounds "
                             f"[{self.lower}, {self.upper}]")


def bound_side(value: float, lower: float, upper: float, share: float) -> str:
    """``"lower"`` or ``"upper"`` where ``value`` lies within ``share`` of the range ``upper − lower``
    of that bound, else ``""`` (also where the range or the value is not finite)."""
    span = upper - lower
    if not (np.isfinite(span) and span > 0 and np.isfinite(value)):
        return ""
    return "lower" if value - lower <= share * span else "upper" if upper - value <= share * span else ""


#: Settling time of a component with states that does not state its own [s]: a day, the period of
#: building operation (an FMU's dynamics are unknown; a PI loop's are slow, see PIController).
DEFAULT_SETTLING_S = 86400.0


class ComponentModel:
    """Base class of component models: declare ports, parameters and states; implement :meth:`step`.

    Subclasses set the class attributes ``inputs``, ``outputs``, ``parameters`` and ``states`` and
    keep ``__init__`` free of logic. Docstrings give the equations and the units.
    """

    inputs: ClassVar[tuple[Port, ...]] = ()
    outputs: ClassVar[tuple[Port, ...]] = ()
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    states: ClassVar[tuple[str, ...]] = ()
    #: One :meth:`step` advances a whole ensemble with numpy at about the cost of one member (False
    #: when each member is stepped on its own, an FMU instance per member).
    vectorised: ClassVar[bool] = True
    #: The sign of the heat the component can give the air passing it: +1 only adds heat (a coil fed
    #: with hot water), −1 only removes it (a chilled-water coil), 0 either or none. The diagnosis
    #: demotes an effect that puts heat where the component has no source (``docs/diagnosis.md``).
    air_heat_sign: ClassVar[int] = 0
    #: An effect's parameter that is a heat rate into the air [W] (its sign is checked against the
    #: host's :attr:`air_heat_sign`); None for effects that add no heat of their own.
    heat_rate_parameter: ClassVar[str | None] = None
    #: An effect's parameter that is a valve's stem position (a leak's, a stuck stem's): the diagnosis
    #: states it too as the flow share its host's valve passes there (:meth:`valve_flow_share`).
    stem_position_parameter: ClassVar[str | None] = None
    #: An effect's parameter that is the temperature of unmeasured surroundings [°C] (a casing's or
    #: duct's): the diagnosis says where it fits colder than every temperature the unit measures.
    surroundings_temperature_parameter: ClassVar[str | None] = None
    #: An effect's reading of its host's parameters, by name: the simulator passes the host's values
    #: (a valve effect reads the actuator's dead band, to act on the stem the actuator sets). A host
    #: without such a parameter passes nothing, and the effect does without.
    host_parameters: ClassVar[tuple[str, ...]] = ()
    #: An effect whose size is a share of its host's quantity: the host's parameters that scale that
    #: quantity (a motor's heat, a share of the fan's nominal power). Where the host has none of them
    #: from the graph or a fit (an assumed default), the share's upper bound is no physical limit.
    share_of_host_parameters: ClassVar[tuple[str, ...]] = ()
    #: A component modelling a valve: the parameters that shape its :meth:`valve_flow_share`.
    valve_characteristic: ClassVar[tuple[str, ...]] = ()
    #: How long the states take to forget their start [s], at the slowest the priors allow: the
    #: warm-up a simulated window needs (:func:`service.data.model_series.model_warmup_s`). None: a
    #: day for a model with states (:data:`DEFAULT_SETTLING_S`), nothing for a memoryless one.
    settling_s: ClassVar[float | None] = None
    #: How long the outputs remember a wrong start state at typical parameters [s]: when the warm-up
    #: before a window reaches back past the data's first step, the state it gives the window is a
    #: guess, and calibration leaves this much of the window unscored
    #: (:meth:`service.calibration.model_data.ModelData.unscored_start_s`). Shorter than :attr:`settling_s`,
    #: which holds at the priors' slowest corner.
    start_memory_s: ClassVar[float] = 0.0

    @classmethod
    def valve_flow_share(cls, position: float, params: Mapping[str, float]) -> float:
        """The flow coefficient of the valve this component models at stem ``position`` (0–1), as a share
        of the fully open one, with ``params`` (the component's, by name); NaN where it models none."""
        return float("nan")

    @classmethod
    def parameters_fixed_by_measurement(cls, measured_outputs: frozenset[str]) -> dict[str, float]:
        """Parameters this model fixes instead of estimating, by which of its outputs a calibration
        target measures (``measured_outputs``, port names): a parameter only a measured output can
        pin. The assembly maps them (the graph's own value wins). None by default."""
        return {}

    @classmethod
    def memoryless(cls) -> bool:
        """Outputs at t_k depend on the inputs at t_k alone: no declared state and no
        :meth:`initial_state` of its own (the simulator then evaluates it over all steps at once)."""
        return not cls.states and cls.initial_state is ComponentModel.initial_state

    @classmethod
    def settling_time_s(cls) -> float:
        """:attr:`settling_s`, or its default."""
        if cls.settling_s is not None:
            return cls.settling_s
        return 0.0 if cls.memoryless() else DEFAULT_SETTLING_S

    @classmethod
    def input_names(cls) -> tuple[str, ...]:
        return tuple(p.name for p in cls.inputs)

    @classmethod
    def output_names(cls) -> tuple[str, ...]:
        return tuple(p.name for p in cls.outputs)

    @classmethod
    def parameter(cls, name: str) -> Parameter:
        for parameter in cls.parameters:
            if parameter.name == name:
                return parameter
        raise KeyError(f"{cls.__name__} has no parameter {name!r}")

    @classmethod
    def fallback_inputs(cls) -> dict[str, str]:
        """Input port → the parameter that stands in for it where nothing feeds it (:class:`Port`)."""
        return {p.name: p.fallback_parameter for p in cls.inputs if p.fallback_parameter is not None}

    @classmethod
    def input_or_fallback(cls, name: str, inputs: Signals, params: Params) -> np.ndarray:
        """The input ``name`` where it is fed, else the parameter standing in for it (:class:`Port`)."""
        return inputs[name] if name in inputs else params[cls.port(name).fallback_parameter]

    @classmethod
    def port(cls, name: str) -> Port:
        for port in cls.inputs + cls.outputs:
            if port.name == name:
                return port
        raise KeyError(f"{cls.__name__} has no port {name!r}")

    def initial_state(self, params: Params, inputs: Signals, dt_s: float) -> State:
        """State at the first time step, from the parameters and the first inputs.

        The default is no state. Dynamic models start in steady state with the first inputs.
        """
        return {}

    def step(self, params: Params, inputs: Signals, state: State, dt_s: float) -> Signals:
        """Outputs at ``t_k`` from inputs and state at ``t_k``; advances ``state`` to ``t_{k+1}``."""
        raise NotImplementedError


class SplicedEffect(ComponentModel):
    """An effect spliced into one port of a base component: ``value_out = f(value_in, ...)``.

    Its first input is ``value_in`` and its first output ``value_out``; further inputs (the fan's
    power, an ambient temperature) are mapped by the effect's signature like any component input.
    Every parameter has a ``null`` value at which ``value_out == value_in``.
    """


def first_order_lag_factor(dt_s: float, time_constant_s: np.ndarray) -> np.ndarray:
    """``1 − exp(−Δt/τ)``: the share of the gap a first-order lag closes in one step (τ in s).

    τ = 0 gives 1 (no lag).
    """
    tau = np.asarray(time_constant_s, dtype=float)
    lagging = tau > 0.0
    return np.where(lagging, -np.expm1(-dt_s / np.where(lagging, tau, 1.0)), 1.0)
