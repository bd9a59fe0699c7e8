"""The assembled simulation model: components matched in the graph, their wiring and their parameters.

This is the value object that :mod:`service.model.assembly` produces from a building graph and that the
simulator, the calibrators and the diagnosis consume. It holds IRIs, not store handles, so it can be
pickled to a worker process.

Paper (Bjørnskov, Jradi & Wetter, Sec. 3.3): boundary inputs are measuring devices (and schedules)
with no inputs; calibration targets are measuring devices with exactly one input (Eq. 1); the
parameters to estimate are all parameters minus those mapped from the graph (Eq. 2).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from service.components.component import ComponentModel, Parameter
from service.components.library import load_model_class
from service.matching.signature import Signature

__all__ = [
    "MeasurementLink", "ComponentInstance", "Connection", "ParameterRef", "ParameterDrift", "AssembledModel",
    "mapped_values_outside_bounds", "DAY_S",
]

#: Seconds in a day: a linear drift's rate is per day.
DAY_S = 86400.0


@dataclass(frozen=True)
class MeasurementLink:
    """Where a measuring device's series comes from: its node, the time-series id a CSV column
    may carry instead of the IRI, and the QUDT unit the values are recorded in."""

    node: str
    series_id: str | None
    unit: str | None


@dataclass(frozen=True, kw_only=True)
class ComponentInstance:
    """One match of a signature: the model that represents ``modeled_nodes`` of the building graph."""

    iri: str
    signature: Signature
    bindings: dict[str, str]  # pattern node id → bound IRI or literal lexical form
    modeled_nodes: tuple[str, ...]  # building node IRIs, in the signature's order
    mapped_parameters: dict[str, float]  # parameter name → value in the model's unit
    measurement: MeasurementLink | None = None

    @property
    def model_class(self) -> type[ComponentModel]:
        return load_model_class(self.signature)

    @property
    def node(self) -> str:
        """The first node this component represents (its name in reports)."""
        return self.modeled_nodes[0]


@dataclass(frozen=True)
class Connection:
    """Output ``source_port`` of component ``source`` feeds input ``target_port`` of ``target``."""

    source: str
    source_port: str
    target: str
    target_port: str


@dataclass(frozen=True)
class ParameterRef:
    """A parameter of one component instance, with its value or prior bounds in the model's unit."""

    component: str
    spec: Parameter
    value: float | None = None  # mapped from the graph, or fixed; None when it is to be estimated

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def key(self) -> str:
        """``<component IRI>#<parameter name>``: unique across the model."""
        return f"{self.component}#{self.spec.name}"


@dataclass(frozen=True)
class ParameterDrift:
    """A parameter that changes over time from ``onset_s`` (s since the data's first step), relative
    to its constant value p₀: ``"linear"`` p(t) = p₀·(1 + r·(t − t₀)/day), ``"step"`` p(t) = p₀·(1 + j),
    for t ≥ t₀; p₀ before. Its size, r [1/d] or j [1], is the estimated parameter ``size_key``."""

    parameter_key: str
    shape: str
    onset_s: float
    size_key: str

    def factor(self, size: np.ndarray, time_s: np.ndarray) -> np.ndarray:
        """p(t)/p₀, ``ndarray[n_ensemble, n_steps]``, for sizes ``ndarray[n_ensemble]`` at the times
        ``ndarray[n_steps]`` (s since the data's first step)."""
        elapsed = np.asarray(time_s, dtype=float) - self.onset_s
        change = np.maximum(elapsed, 0.0) / DAY_S if self.shape == "linear" else (elapsed >= 0.0).astype(float)
        return 1.0 + np.asarray(size, dtype=float)[:, None] * change[None, :]


@dataclass(kw_only=True)
class AssembledModel:
    """The simulation model of one building model: its components by IRI, their connections, the
    boundary inputs and targets (Eq. 1), and the mapped and estimated parameters (Eq. 2)."""

    components: dict[str, ComponentInstance]
    connections: tuple[Connection, ...]
    boundary_inputs: tuple[str, ...]  # component IRIs of measuring devices with no input
    targets: tuple[str, ...]  # component IRIs of measuring devices with one input
    mapped_parameters: tuple[ParameterRef, ...]
    estimated_parameters: tuple[ParameterRef, ...]  # the columns of θ, in this order
    building_graph: str = ""
    notes: tuple[str, ...] = field(default_factory=tuple)
    drifts: tuple[ParameterDrift, ...] = ()  # parameters that change over time, one drift per parameter

    def drift_factors(self, theta: np.ndarray, time_s: np.ndarray) -> dict[str, np.ndarray]:
        """Drifting parameter key → its factor p(t)/p₀ ``ndarray[n_ensemble, n_steps]`` for θ
        ``ndarray[n_ensemble, n_estimated]`` at the times ``ndarray[n_steps]`` (s since the data's first step)."""
        column = {ref.key: j for j, ref in enumerate(self.estimated_parameters)}
        return {d.parameter_key: d.factor(np.asarray(theta)[:, column[d.size_key]], time_s) for d in self.drifts}

    def component_for_node(self, node_iri: str) -> ComponentInstance | None:
        for component in self.components.values():
            if node_iri in component.modeled_nodes:
                return component
        return None

    def targets_reached_from(self, sources: Iterable[str]) -> set[str]:
        """The targets (component IRIs) that an output of the components ``sources`` reaches along the
        connections, each component on the way passing every input on to every output (a controller's
        loop included): the sensors an effect spliced there can move at all."""
        feeds = defaultdict(set)
        for connection in self.connections:
            feeds[connection.source].add(connection.target)
        seen, stack = set(sources), list(sources)
        while stack:
            for following in feeds[stack.pop()] - seen:
                seen.add(following)
                stack.append(following)
        return seen & set(self.targets)

    def measurement(self, component_iri: str) -> MeasurementLink:
        link = self.components[component_iri].measurement
        if link is None:
            raise KeyError(f"{component_iri} is not a measuring device")
        return link


def mapped_values_outside_bounds(mapped: Iterable[ParameterRef], components: Mapping[str, ComponentInstance]) -> list[str]:
    """One sentence per parameter the graph maps to a value outside its physical bounds, or to no
    number (a nominal power of 80 kW for a fan whose signature allows 50 W – 50 kW is a typo or a
    wrong unit), in the parameter's unit."""
    return [f"{ref.spec.name} of {components[ref.component].node} is mapped from the graph to {ref.value:g} "
            f"{ref.spec.unit}, outside its bounds [{ref.spec.lower:g}, {ref.spec.upper:g}] {ref.spec.unit}"
            for ref in mapped if ref.value is not None and not ref.spec.lower <= ref.value <= ref.spec.upper]
