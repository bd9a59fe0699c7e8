"""An assembled model bound to its measured data: windows, simulation and calibration problems.

:class:`ModelData` is where the graph world (device IRIs, QUDT units) meets the numeric one: it
turns a time window into a :class:`~service.calibration.problem.CalibrationProblem` whose targets
are keyed by the sensors' building-node IRIs, the names users see in every report. The series and
their units come from :mod:`service.data.model_series`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from service.calibration.problem import CalibrationProblem
from service.data.measurements import MeasuredData
from service.data.model_series import (
    GAP_RECOVERY_S,
    SETTLING_S,
    check_mapped_parameters,
    model_start_memory_s,
    model_warmup_s,
    warmup_period_steps,
)
from service.errors import CalibrationError
from service.graph.namespaces import local_name
from service.model.assembled_model import AssembledModel
from service.model.simulator import SimulationResult, Simulator, held_over_gaps, warmup_index

__all__ = ["DEFAULT_GP_INPUTS", "ModelData", "gp_input_name"]

#: The discrepancy GP's inputs unless the user names others: time alone (hours since the data's start).
DEFAULT_GP_INPUTS: tuple[str, ...] = ("time",)


def gp_input_name(node: str) -> str:
    """A GP input's name, as its length scale is named: ``time``, else the boundary input's local name."""
    return node if node == "time" else local_name(node)


@dataclass
class ModelData:
    """``model`` with ``data``; ``substeps`` sub-divides the data step for the simulation."""

    model: AssembledModel
    data: MeasuredData
    substeps: int = 1
    #: ``ndarray[n_steps]`` of bool: the steps where targets are compared (an operating filter,
    #: :mod:`service.data.operating_filter`); None: every step.
    compared: np.ndarray | None = None
    #: Warm-up simulated before every window, s; None: :func:`model_warmup_s`.
    warmup_s: float | None = None

    def __post_init__(self) -> None:
        check_mapped_parameters(self.model)
        if self.warmup_s is None:
            self.warmup_s = model_warmup_s(self.model)
        nodes = {self.model.measurement(c).node: c for c in self.model.boundary_inputs + self.model.targets}
        missing = sorted(n for n in nodes if n not in self.data.series)
        if missing:
            raise CalibrationError(f"{self.data.source} has no series for {', '.join(missing)}")
        self.node_of = {c: self.model.measurement(c).node for c in nodes.values()}
        self.target_nodes = tuple(self.node_of[c] for c in self.model.targets)
        self.simulator = Simulator(self.model, self.data.step_s, self.substeps)
        self.units = {self.node_of[c]: self.data.units[self.node_of[c]] for c in self.model.targets}

    @property
    def warmup_steps(self) -> int:
        return int(round(self.warmup_s / self.data.step_s))

    def boundary(self, window: slice) -> dict[str, np.ndarray]:
        """Component IRI → measured series over ``window`` preceded by its warm-up
        (:func:`~service.model.simulator.warmup_index`; targets included: they seed delayed inputs)."""
        index = warmup_index(window, self.warmup_steps, warmup_period_steps(self.data.n_steps, self.data.step_s))
        return {c: self.data.series[node][index] for c, node in self.node_of.items()}

    def run(self, window: slice, theta: np.ndarray, fixed: Mapping[str, float] | None = None, *,
            record: Sequence[tuple[str, str]] | None = None,
            factors: Mapping[str, np.ndarray] | None = None) -> SimulationResult:
        """Simulate ``window`` for θ ``ndarray[n_ensemble, n_estimated]`` after :attr:`warmup_s` of
        warm-up: the states at the window's start are those the measured operation before it leaves
        (a controller's integral, a coil's water), not a cold start. The model's drifting parameters
        (:class:`~service.model.assembled_model.ParameterDrift`) and ``factors`` (parameter key →
        ``ndarray[n_ensemble, n_steps]`` over the warm-up and the window, see :meth:`time_s`) change
        over time."""
        theta = np.atleast_2d(theta)
        if self.model.drifts:
            factors = self.model.drift_factors(theta, self.time_s(window)) | dict(factors or {})
        return self._simulate(window, theta, fixed, record, factors)

    def _simulate(self, window: slice, theta: np.ndarray, fixed: Mapping[str, float] | None,
                  record: Sequence[tuple[str, str]] | None,
                  factors: Mapping[str, np.ndarray] | None) -> SimulationResult:
        """:meth:`run`'s simulation, the drifts' factors included: the model's simulator after the warm-up."""
        return self.simulator.run(self.boundary(window), theta, fixed=fixed, record=record,
                                  warmup_steps=self.warmup_steps, factors=factors)

    def time_s(self, window: slice) -> np.ndarray:
        """Seconds since the data's first step of each step :meth:`run` simulates for ``window``: its
        warm-up (negative before the data's start) and the window."""
        return np.arange(window.start - self.warmup_steps, window.stop) * self.data.step_s

    def observed(self, window: slice) -> dict[str, np.ndarray]:
        """Target node → observed series in ``window``: NaN where not measured; NaN where a
        boundary input is missing (a gap longer than the interpolation limit: the simulator holds
        the input's last value there, so the model is not compared with the measurement) and for
        :data:`GAP_RECOVERY_S` after such a gap (the model's states — thermal masses, a controller's
        integral — come out of it off, and take that long to follow the inputs again); and NaN
        outside the operating filter (``compared``)."""
        recovery = int(round(GAP_RECOVERY_S / self.data.step_s))
        span = warmup_index(window, recovery)  # a gap just before the window reaches into it
        inputs_missing = np.zeros(span.size, dtype=bool)
        for component in self.model.boundary_inputs:
            inputs_missing |= ~np.isfinite(self.data.series[self.node_of[component]][span])
        after_gap = (np.convolve(inputs_missing, np.ones(recovery + 1, dtype=bool))[: span.size] > 0)[recovery:]
        compared = (np.ones(self.data.n_steps, dtype=bool) if self.compared is None else self.compared)[window]
        keep = compared & ~after_gap
        return {self.node_of[c]: np.where(keep, self.data.series[self.node_of[c]][window], np.nan)
                for c in self.model.targets}

    def simulate_targets(self, window: slice, theta: np.ndarray, fixed: Mapping[str, float] | None = None, *,
                         factors: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Target node → ``ndarray[n_ensemble, n_steps]`` for θ ``ndarray[n_ensemble, n_estimated]``
        (``factors``: :meth:`run`)."""
        result = self.run(window, theta, fixed, record=[(c, "measured_value") for c in self.model.targets],
                          factors=factors)
        return {self.node_of[c]: result.target(c) for c in self.model.targets}

    def simulate_all(self, window: slice, theta: np.ndarray) -> SimulationResult:
        """Every output of every component (for plots and the residual-dependence search)."""
        return self.run(window, theta)

    def non_finite_source(self, window: slice, theta: np.ndarray) -> str | None:
        """Where the simulation of ``window`` at θ ``ndarray[n_estimated]`` first gives NaN or an
        infinite value: the component output with the earliest such step (the most upstream one, in
        simulation order, on a tie), named with its signature and model; None when all is finite."""
        result = self.simulate_all(window, theta)
        first = None
        for order, iri in enumerate(self.simulator.order):
            for port in self.model.components[iri].model_class.output_names():
                bad = np.flatnonzero(~np.isfinite(result.outputs[(iri, port)][0]))
                if bad.size and (first is None or (bad[0], order) < first[:2]):
                    first = (int(bad[0]), order, iri, port)
        if first is None:
            return None
        step, _, iri, port = first
        instance = self.model.components[iri]
        model = instance.signature.fmu.name if instance.signature.fmu is not None else instance.signature.model
        stamp = self.data.timestamps[window][step]
        return (f"{instance.node} (component {iri}, signature {instance.signature.id}, model {model}): output {port} is "
                f"{result.outputs[(iri, port)][0][step]} from step {step} ({stamp}) at the default parameters")

    def gp_input_nodes(self, names: Sequence[str]) -> tuple[str, ...]:
        """The discrepancy GP's inputs named by the user: ``"time"``, or a boundary input's node IRI,
        local name or CSV column, each → ``"time"`` or the node IRI.

        :raises CalibrationError: naming what is not one, with the names that are.
        """
        boundary = [self.node_of[c] for c in self.model.boundary_inputs]
        known = {"time": "time"} | {n: n for n in boundary} | {local_name(n): n for n in boundary} | {
            self.data.columns[n]: n for n in boundary if n in self.data.columns}
        unknown = [name for name in names if name not in known]
        if unknown:
            offered = ", ".join(["time"] + sorted(local_name(n) for n in boundary))
            targets = set(self.target_nodes) | {local_name(n) for n in self.target_nodes} | {
                self.data.columns[n] for n in self.target_nodes if n in self.data.columns}
            why = ("a target's measurements would feed the discrepancy of what it measures" if set(unknown) & targets
                   else "no device or column of the model has that name")
            raise CalibrationError(f"GP input(s) {', '.join(map(repr, unknown))} are no boundary input of the model "
                                   f"({why}): use {offered}, a node IRI or its CSV column")
        return tuple(dict.fromkeys(known[name] for name in names))

    def _gp_input_series(self, name: str, window: slice) -> np.ndarray:
        """One GP input over ``window``: hours since the data's first step for ``"time"``, else the
        boundary node's series with a gap holding the last value (the first value before it)."""
        if name == "time":
            return np.arange(window.start, window.stop) * self.data.step_s / 3600.0
        values = self.data.series[name][window]
        if not np.isfinite(values).any():
            raise CalibrationError(f"GP input {name} has no measured value in the window")
        return held_over_gaps(values)

    def unscored_start_s(self, window: slice) -> float:
        """Seconds at the start of ``window`` that are simulated but not scored: :data:`SETTLING_S`,
        or what is left of the model's start memory (:func:`model_start_memory_s`) after the measured
        data before the window, when longer: before the data's first step the warm-up repeats the
        first day, and the states it leaves (a controller's integral) are a guess, not the
        building's (its day before differed). A window deep enough in the data starts from a warm-up
        on measured operation."""
        history_s = (window.start or 0) * self.data.step_s
        return max(SETTLING_S, model_start_memory_s(self.model) - history_s)

    def unscored_start_steps(self, window: slice, settling_s: float | None = None) -> int:
        """Data steps at the start of ``window`` that are not scored: ``settling_s`` seconds, or
        :meth:`unscored_start_s` when None."""
        unscored_s = self.unscored_start_s(window) if settling_s is None else settling_s
        return int(round(unscored_s / self.data.step_s))

    def default_theta(self) -> np.ndarray:
        return np.array([ref.spec.default for ref in self.model.estimated_parameters])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        refs = self.model.estimated_parameters
        return np.array([r.spec.lower for r in refs]), np.array([r.spec.upper for r in refs])

    def problem(
        self, window: slice | Sequence[slice], *, default: np.ndarray | None = None,
        fixed: Mapping[str, float] | None = None, target_scales: Mapping[str, float] | None = None,
        gp_inputs: Sequence[str] = DEFAULT_GP_INPUTS, settling_s: float | None = None,
    ) -> CalibrationProblem:
        """The calibration problem of ``window`` (or of several windows, concatenated; each is
        simulated on its own): θ = the model's estimated parameters.

        :param default: a plausible θ screened with the start candidates (the components'
            defaults when None).
        :param target_scales: residual scales per target node (e.g. the training window's, so a
            test window weighs alike).
        :param gp_inputs: the discrepancy GP's inputs, named as :meth:`gp_input_nodes` takes them:
            ``"time"`` (hours since the data's first step) and boundary inputs by node IRI, local name
            or CSV column (their measured series, in the simulator's unit; a gap holds the last
            value); empty: none (the calibrator's time index).
        :param settling_s: the first ``settling_s`` seconds of each window are simulated but not
            compared: the warm-up settles the model's states, it cannot give them the building's.
            None: :meth:`unscored_start_s` of each window (an hour; six with a PI loop at the
            data's start).
        :raises CalibrationError: a GP input that is neither time nor a boundary input (named, with those
            that are).
        """
        gp_inputs = self.gp_input_nodes(gp_inputs)
        windows = [window] if isinstance(window, slice) else list(window)
        lower, upper = self.bounds()
        start = self.default_theta() if default is None else np.clip(np.asarray(default, float), lower, upper)
        observed: dict[str, list[np.ndarray]] = {}
        for part in windows:
            settling = self.unscored_start_steps(part, settling_s)
            for node, values in self.observed(part).items():
                values = values.copy()
                values[:settling] = np.nan
                observed.setdefault(node, []).append(values)
        empty = [node for node, parts in observed.items() if not any(np.isfinite(p).any() for p in parts)]
        if empty:
            raise CalibrationError("; ".join(
                f"target {local_name(node)} (column {self.data.columns.get(node, '?')!r}) has no measurements in the "
                "window beyond its warm-up: choose a window where the column has values" for node in empty))
        columns = [np.concatenate([self._gp_input_series(name, w) for w in windows]) for name in gp_inputs]

        def simulate(theta: np.ndarray) -> dict[str, np.ndarray]:
            runs = [self.simulate_targets(part, theta, fixed) for part in windows]
            return {node: np.concatenate([run[node] for run in runs], axis=1) for node in runs[0]}

        return CalibrationProblem(
            parameter_names=tuple(ref.key for ref in self.model.estimated_parameters),
            lower=lower, upper=upper, simulate=simulate,
            observed={node: np.concatenate(parts) for node, parts in observed.items()}, units=self.units,
            default=start, target_scales=dict(target_scales or {}),
            gp_inputs=np.column_stack(columns) if columns else None,
            gp_input_names=tuple(gp_input_name(name) for name in gp_inputs) or None,
            vectorised_simulate=all(c.model_class.vectorised for c in self.model.components.values()),
        )
