"""Drift, for what the catalog lacks: an estimated parameter of a failing component that changes over time.

A drift candidate is (component, parameter, shape): ``linear``, p(t) = p₀·(1 + r·(t − t₀)/day) from
the test window's start t₀ (the model matched the training data; from then on the parameter drifts),
or ``step``, p(t) = p₀·(1 + j) from t_s, picked by the fit (on a 6-hour grid of the data's clock over
the fit windows, then among the data steps around the best) and counted as a freed parameter.
Candidates only for the components the localization suspects for the most-failing sensor, at most
:data:`MAX_PARAMETERS_PER_COMPONENT` each per failing sensor: those a :data:`PROBE_CHANGE` change from
the test window's start moves that sensor most. They are refitted and ranked like any effect
(:mod:`service.diagnosis.candidates`). The method: ``docs/diagnosis.md``, "Drift".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from service.calibration.model_data import ModelData
from service.components.component import Parameter
from service.diagnosis.localization import FailureLocation
from service.diagnosis.plausibility import BOUND_SHARE
from service.diagnosis.ranking import EffectEvidence
from service.graph.namespaces import GTR, local_name
from service.graph.units import quantity_text
from service.model.assembled_model import DAY_S, AssembledModel, ParameterDrift, ParameterRef

__all__ = ["DriftCandidate", "DriftEvidence", "drift_candidates", "drifting_components", "drifting_parameter",
           "step_onset", "drift_identity", "drift_fields", "drift_sentence", "drift_beyond_range",
           "MAX_PARAMETERS_PER_COMPONENT"]

#: Parameters per suspect component and failing sensor that get drift candidates (both shapes each).
MAX_PARAMETERS_PER_COMPONENT = 2
#: The relative change from the test window's start by which the parameters are screened.
PROBE_CHANGE = 0.1
#: A parameter whose :data:`PROBE_CHANGE` moves no failing sensor by this many noise levels (RMS over
#: the test window) gets no candidate: where the model fails, its drift would hardly show.
MIN_SENSITIVITY = 0.5
#: A step's onset grid: every 6 h of the data's clock.
ONSET_GRID_S = 6 * 3600.0
#: The jumps j laid on every onset of the grid when the onset is picked.
JUMP_PROBES = (-0.5, -0.25, -0.1, 0.1, 0.25, 0.5)
#: The drifting parameter stays within these multiples of p₀: a step's j and, over the data after
#: t₀, a linear drift's r·(t − t₀)/day.
LOWEST_FACTOR, HIGHEST_FACTOR = 0.1, 2.0


class DriftCandidate(NamedTuple):
    """A drift of one parameter at one building node, the model that carries it, and for a step the
    data steps its onset is picked from."""

    node: str
    model: AssembledModel
    onsets: tuple[int, ...]


@dataclass
class DriftEvidence(EffectEvidence):
    """The evidence of a drift candidate: ``parameter`` (its key) changes with ``shape`` from
    ``onset`` (the data's time stamp)."""

    parameter: str = ""
    shape: str = ""
    onset: str = ""

    def to_dict(self) -> dict:
        return super().to_dict() | {"drift": {"parameter": self.parameter.rsplit("#", 1)[-1], "shape": self.shape,
                                              "onset": self.onset}}


def drift_identity(drift: ParameterDrift) -> tuple[str, str, str]:
    """(effect id, IRI, label) of a drift candidate: ``LinearDrift/air_side_conductance``, its IRI
    among graphtwin's resources, "Linear drift of air_side_conductance"."""
    name = drift.parameter_key.rsplit("#", 1)[-1]
    effect = f"{drift.shape.capitalize()}Drift/{name}"
    words = "Linear drift" if drift.shape == "linear" else "Step change"
    return effect, GTR.iri(f"drift/{effect}"), f"{words} of {name}"


def drifting_parameter(effect_id: str) -> str | None:
    """The parameter's name in a drift candidate's id (:func:`drift_identity`:
    ``LinearDrift/air_side_conductance`` → ``air_side_conductance``); None for any other id."""
    shape, slash, name = effect_id.partition("/")
    return name if slash and name and shape in ("LinearDrift", "StepDrift") else None


def drift_fields(model: AssembledModel, timestamps: np.ndarray, step_s: float) -> dict:
    """The :class:`DriftEvidence` fields of ``model``'s drift (empty when it has none)."""
    if not model.drifts:
        return {}
    drift = model.drifts[0]
    return {"parameter": drift.parameter_key, "shape": drift.shape,
            "onset": _minute(timestamps[int(round(drift.onset_s / step_s))])}


def drifting_components(model: AssembledModel, locations: Sequence[FailureLocation], worst_sensor: str) -> list[str]:
    """Component IRIs the localization suspects for ``worst_sensor`` (of every location when it has
    none of its own: it inherits its failure), those with estimated parameters and a vectorised model."""
    own = [loc for loc in locations if loc.failing_sensor == worst_sensor] or list(locations)
    estimated = {ref.component for ref in model.estimated_parameters}
    found = []
    for node in sorted({n for loc in own for n in loc.components}):
        component = model.component_for_node(node)
        if (component is not None and component.iri in estimated and component.model_class.vectorised
                and component.iri not in found):
            found.append(component.iri)
    return found


def _sensitive_parameters(md: ModelData, theta: np.ndarray, components: Sequence[str], test: slice,
                          noise: Mapping[str, float]) -> list[str]:
    """Per component and per failing sensor of ``noise`` (node → σ), the keys of the at most
    :data:`MAX_PARAMETERS_PER_COMPONENT` estimated parameters that can drift (``Parameter.drifts``)
    whose :data:`PROBE_CHANGE` from ``test``'s start moves that sensor most, by at least
    :data:`MIN_SENSITIVITY` σ RMS (one simulate call). Per sensor, so that a sensor failing less than
    another still gets the drifts it would show."""
    keys = [ref.key for ref in md.model.estimated_parameters if ref.component in components and ref.spec.drifts]
    if not keys:
        return []
    ensemble = np.repeat(np.asarray(theta, dtype=float)[None, :], len(keys) + 1, axis=0)
    after = (md.time_s(test) >= test.start * md.data.step_s).astype(float)
    factors = {}
    for member, key in enumerate(keys, start=1):
        factor = np.ones((len(keys) + 1, after.size))
        factor[member] += PROBE_CHANGE * after
        factors[key] = factor
    predicted = md.simulate_targets(test, ensemble, factors=factors)
    component_of = {ref.key: ref.component for ref in md.model.estimated_parameters}
    members = [[k for k in range(len(keys)) if component_of[keys[k]] == component] for component in components]
    chosen = []
    for node, sigma in noise.items():
        moved = np.sqrt(np.nanmean((predicted[node][1:] - predicted[node][0]) ** 2, axis=1)) / sigma
        for own in members:
            ranked = sorted(own, key=lambda k: -moved[k])
            chosen += [keys[k] for k in ranked[:MAX_PARAMETERS_PER_COMPONENT]
                       if moved[k] >= MIN_SENSITIVITY and keys[k] not in chosen]
    return chosen


def _onset_grid(md: ModelData, windows: Sequence[slice]) -> tuple[int, ...]:
    """Data steps inside ``windows`` where the data's clock passes a multiple of :data:`ONSET_GRID_S`,
    leaving a grid interval of fitted data before the onset and after it."""
    seconds = md.data.timestamps.astype("datetime64[s]").astype(np.int64)
    interval = int(round(ONSET_GRID_S / md.data.step_s))
    steps = []
    for window in windows:
        period = seconds[window] // int(ONSET_GRID_S)
        starts = window.start + 1 + np.flatnonzero(np.diff(period) != 0)
        steps += [int(k) for k in starts if window.start + interval <= k <= window.stop - interval]
    return tuple(steps)


def _with_drift(model: AssembledModel, key: str, shape: str, onset_s: float, days_after: float) -> AssembledModel:
    """``model`` with parameter ``key`` drifting: its size (r [1/d] or j [1], null 0, bounds from
    :data:`LOWEST_FACTOR` and :data:`HIGHEST_FACTOR`; a rate's over ``days_after`` days) estimated too."""
    ref = next(r for r in model.estimated_parameters if r.key == key)
    if shape == "linear":
        spec = Parameter(f"{ref.name}_drift_per_day", "1/d", 0.0, (LOWEST_FACTOR - 1.0) / days_after,
                         (HIGHEST_FACTOR - 1.0) / days_after, f"relative change per day of {ref.spec.description}", null=0.0)
    else:
        spec = Parameter(f"{ref.name}_step", "1", 0.0, LOWEST_FACTOR - 1.0, HIGHEST_FACTOR - 1.0,
                         f"relative step of {ref.spec.description}", null=0.0)
    size = ParameterRef(ref.component, spec)
    return replace(model, estimated_parameters=model.estimated_parameters + (size,),
                   drifts=(ParameterDrift(key, shape, onset_s, size.key),))


def drift_candidates(md: ModelData, theta: np.ndarray, components: Sequence[str], *, test: slice,
                     fit_windows: Sequence[slice], noise: Mapping[str, float]) -> list[DriftCandidate]:
    """Both shapes for the parameters of ``components`` a drift could show at the failing sensors
    (``noise``: node → σ), screened at the base θ ``ndarray[n_estimated]`` on the ``test`` window.
    A linear drift starts at ``test``'s start; a step's onset is picked later among its ``onsets``
    in ``fit_windows`` (:func:`step_onset`); no step without an onset on the grid."""
    keys = _sensitive_parameters(md, theta, components, test, noise)
    onsets = _onset_grid(md, fit_windows)
    start_s = test.start * md.data.step_s
    days_after = (test.stop - test.start) * md.data.step_s / DAY_S
    component_of = {ref.key: ref.component for ref in md.model.estimated_parameters}
    found = []
    for key in keys:
        node = md.model.components[component_of[key]].node
        found.append(DriftCandidate(node, _with_drift(md.model, key, "linear", start_s, days_after), ()))
        if onsets:
            found.append(DriftCandidate(node, _with_drift(md.model, key, "step", onsets[0] * md.data.step_s, days_after),
                                        onsets))
    return found


def step_onset(md: ModelData, windows: Sequence[slice], starts: Sequence[np.ndarray], onsets: Sequence[int],
               target_scales: Mapping[str, float]) -> AssembledModel:
    """``md``'s model (a step drift) with its onset where it fits ``windows`` best: the step of
    ``onsets`` (the grid) with each of :data:`JUMP_PROBES` on each θ of ``starts``
    (``ndarray[n_estimated]``), then every data step within half a grid interval of the best, with
    that jump ×0.7, ×1, ×1.4 on that θ: two simulate calls per window."""
    drift = md.model.drifts[0]
    problem = md.problem(list(windows), target_scales=target_scales)

    def cost(onset_steps: np.ndarray, jumps: np.ndarray, thetas: np.ndarray) -> np.ndarray:
        runs = []
        for window in windows:
            factor = 1.0 + jumps[:, None] * (md.time_s(window)[None, :] >= onset_steps[:, None] * md.data.step_s)
            runs.append(md.simulate_targets(window, thetas, factors={drift.parameter_key: factor}))
        outputs = {node: np.concatenate([run[node] for run in runs], axis=1) for node in problem.observed}
        return np.sum(problem.weighted_residuals(outputs) ** 2, axis=1)

    grid = [(k, j, np.asarray(s, dtype=float)) for s in starts for k in onsets for j in JUMP_PROBES]
    onset, jump, theta = grid[int(np.argmin(cost(*(np.array(column) for column in zip(*grid)))))]
    reach = int(round(0.5 * ONSET_GRID_S / md.data.step_s))
    inside = [k for k in range(onset - reach, onset + reach + 1) if any(w.start < k < w.stop for w in windows)]
    fine = [(k, jump * factor, theta) for k in inside for factor in (0.7, 1.0, 1.4)]
    best = fine[int(np.argmin(cost(*(np.array(column) for column in zip(*fine)))))][0]
    return replace(md.model, drifts=(replace(drift, onset_s=float(best * md.data.step_s)),))


def _drifted(model: AssembledModel, theta: np.ndarray, step_s: float, end: int) -> tuple[ParameterRef, float, float]:
    """(the drifting parameter, its value p₀ at the onset, its value at data step ``end`` — a linear
    drift's p₀·(1 + r·(t_end − t₀)/day), a step's p₀·(1 + j))."""
    drift = model.drifts[0]
    column = {ref.key: j for j, ref in enumerate(model.estimated_parameters)}
    ref = model.estimated_parameters[column[drift.parameter_key]]
    value, size = theta[column[drift.parameter_key]], theta[column[drift.size_key]]
    days = (end - int(round(drift.onset_s / step_s))) * step_s / DAY_S if drift.shape == "linear" else 1.0
    return ref, float(value), float(value * (1.0 + size * days))


def drift_beyond_range(model: AssembledModel, theta: np.ndarray, step_s: float, end: int) -> str:
    """Why a fitted drift is implausible: the parameter it moves leaves its range (the prior's bounds:
    what the component is built and run for, a physical limit for a fraction) by data step ``end``;
    empty when it stays."""
    ref, _, later = _drifted(model, theta, step_s, end)
    spec = ref.spec
    slack = BOUND_SHARE * (spec.upper - spec.lower)
    if spec.lower - slack <= later <= spec.upper + slack:
        return ""
    return (f"the {ref.name} it drifts to, {quantity_text(later, spec.unit, '.4g')}, lies outside its range "
            f"{spec.lower:g}–{quantity_text(spec.upper, spec.unit, 'g')}")


def drift_sentence(model: AssembledModel, theta: np.ndarray, standard_errors: np.ndarray, timestamps: np.ndarray,
                   step_s: float, end: int) -> str:
    """The drift in words, with the parameter's meaning and unit: "the air_side_conductance of
    heating_coil_air_side (air-side hA at 2 kg/s, hA_a) falls 1.5 ± 0.2 % a day from 2026-01-19
    00:00: 1610 W/K then, 1540 W/K at 2026-01-21 23:50" (``end``: the last data step judged), or
    "… drops 20 ± 3 % at 2026-01-20 06:00: from 1610 to 1290 W/K"; "(not identified)" where the
    size's standard error spans its prior range."""
    drift = model.drifts[0]
    column = {ref.key: j for j, ref in enumerate(model.estimated_parameters)}
    size_spec = model.estimated_parameters[column[drift.size_key]].spec
    size, error = theta[column[drift.size_key]], standard_errors[column[drift.size_key]]
    ref, value, later = _drifted(model, theta, step_s, end)
    onset = int(round(drift.onset_s / step_s))
    what = f"the {ref.name} of {local_name(model.components[ref.component].node)} ({ref.spec.description})"
    change = (f"{100 * abs(size):.2g} ± {100 * error:.1g} %" if np.isfinite(error) and error <= size_spec.upper - size_spec.lower
              else f"{100 * abs(size):.2g} % (not identified)")
    if drift.shape == "linear":
        return (f"{what} {'falls' if size < 0 else 'rises'} {change} a day from {_minute(timestamps[onset])}: "
                f"{quantity_text(value, ref.spec.unit, '.4g')} then, {quantity_text(later, ref.spec.unit, '.4g')} "
                f"at {_minute(timestamps[end])}")
    return (f"{what} {'drops' if size < 0 else 'rises'} {change} at {_minute(timestamps[onset])}: from {value:.4g} to "
            f"{quantity_text(later, ref.spec.unit, '.4g')}")


def _minute(stamp: np.datetime64) -> str:
    """``2026-01-19 06:00``."""
    return str(np.datetime64(stamp, "m")).replace("T", " ")
