"""One answer among look-alikes: which significant candidates the data cannot tell from the answer,
and what would tell them apart.

A candidate is indistinguishable from the answer when their fits and their held-out errors agree
within noise: on the fit windows and on the held-out half alike, their errors differ by no more
than twice the standard error of the difference (a paired test of per-step differences,
autocorrelation counted; in sample, Vuong's test for non-nested models). What
would separate them: a quantity the model computes and no sensor measures where the two fitted
models differ by several sensor accuracies (a sensor the graph lacks, with the triples to add), or
a boundary input held at another level where their predictions at the existing sensors part
(operation the data lack). The method: ``docs/diagnosis.md``, "One answer".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from service.calibration.metrics import effective_sample_fraction
from service.calibration.model_data import ModelData
from service.calibration.problem import INSTRUMENT_ACCURACY_FLOOR, RELATIVE_ACCURACY_FLOOR
from service.diagnosis.ranking import EffectEvidence
from service.graph.namespaces import local_name
from service.graph.units import quantity_text

__all__ = ["Lookalike", "ToldApart", "distance_text", "errors_tie", "indistinguishable", "paired_z", "told_apart"]

#: Two candidates' errors tie within this many standard errors of their paired difference.
TIE_STANDARD_ERRORS = 2.0
#: A difference a sensor would see: this many times its accuracy (RMS over the evaluation half).
SEPARATING_ACCURACIES = 3.0
#: How far a boundary input is moved for "operation the data lack": ± this in K for a temperature,
#: × (1 ∓ this) for any other quantity.
WHAT_IF_KELVIN, WHAT_IF_SHARE = 5.0, 0.4
#: What a sensor of a port's unit is, in the terms the case-study models use: (what it is, its
#: class, the property class it observes, its QUDT unit).
_SENSOR_OF_UNIT = {
    "degC": ("temperature", "s4bldg:Sensor", "saref:Temperature", "unit:DEG_C"),
    "W": ("power", "saref:Meter", "saref:Power", "unit:W"),
    "m3/s": ("air flow", "s4bldg:FlowMeter", "gt:FlowRate", "unit:M3-PER-SEC"),
    "kg/s": ("mass flow", "s4bldg:FlowMeter", "gt:FlowRate", "unit:KiloGM-PER-SEC"),
    "1": ("position", "s4bldg:Sensor", "gt:OpeningPosition", "unit:UNITLESS"),
}


@dataclass(frozen=True)
class Lookalike:
    """A significant candidate the data cannot tell from the answer, and what would separate them."""

    effect: EffectEvidence
    would_separate: tuple[str, ...]

    def to_dict(self) -> dict:
        e = self.effect
        return {"effect": e.effect_iri, "effect_id": e.effect, "target": e.node, "label": e.label,
                "test_improvement": e.test_improvement, "delta_bic": e.delta_bic,
                "would_separate": list(self.would_separate)}


def paired_z(a: np.ndarray | None, b: np.ndarray | None) -> float | None:
    """How far apart two candidates' per-step errors over the same steps (:attr:`EffectEvidence.fit_step_errors`
    or ``evaluation_step_errors``) are: |Σd| over the standard error of the sum of their differences d
    (Var Σd ≈ n·var(d) / (n_eff/n), from d's lag-1 autocorrelation); 0 for fewer than 3 steps or no
    difference; None where either is missing or they cover different steps."""
    if a is None or b is None or a.shape != b.shape:
        return None
    d = a - b
    if d.size < 3 or not np.any(d):
        return 0.0
    standard_error = float(np.sqrt(d.size * np.var(d) / effective_sample_fraction(d)))
    return abs(float(d.sum())) / standard_error if standard_error > 0.0 else float("inf")


def errors_tie(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """True when two candidates' per-step errors are at most :data:`TIE_STANDARD_ERRORS` standard
    errors apart (:func:`paired_z`); False where either is missing or they cover different steps."""
    z = paired_z(a, b)
    return z is not None and z <= TIE_STANDARD_ERRORS


@dataclass(frozen=True)
class ToldApart:
    """A significant candidate the data do tell from the answer: its errors' distance from the
    answer's (:func:`paired_z`) on the fit windows and on the held-out half, or the physics that
    rules it out where the answer's does not."""

    effect: EffectEvidence
    fit_z: float | None
    held_out_z: float | None
    ruled_out: str = ""

    def describe(self) -> str:
        e = self.effect
        if self.ruled_out:
            return f"{e.effect} at {local_name(e.node)}: ruled out by the physics ({self.ruled_out})"
        return f"{e.effect} at {local_name(e.node)}: {distance_text(self.fit_z, self.held_out_z)}"

    def to_dict(self) -> dict:
        e = self.effect
        return {"effect_id": e.effect, "target": e.node, "fit_z": self.fit_z, "held_out_z": self.held_out_z,
                "ruled_out": self.ruled_out or None, "text": self.describe()}


def distance_text(fit_z: float | None, held_out_z: float | None) -> str:
    """How far a candidate's errors lie from the answer's (:func:`paired_z`), as a clause."""
    distances = [(z, where) for z, where in ((fit_z, "fit windows"), (held_out_z, "held-out half")) if z is not None]
    if not distances:
        return "its errors were not paired with the answer's"
    (z, where), rest = distances[0], distances[1:]
    more = "".join(f" and {z_more:.1f} on the {where_more}" for z_more, where_more in rest)
    return (f"its errors lie {z:.1f} standard errors from the answer's on the {where}{more} (they would tie "
            f"within {TIE_STANDARD_ERRORS:g} on both)")


def told_apart(answer: EffectEvidence, ranked: list[EffectEvidence], lookalikes: list[Lookalike]) -> list[ToldApart]:
    """The significant candidates other than ``answer`` and its look-alikes: why each is not the answer."""
    tied = {id(lookalike.effect) for lookalike in lookalikes}
    return [ToldApart(e, paired_z(answer.fit_step_errors, e.fit_step_errors),
                      paired_z(answer.evaluation_step_errors, e.evaluation_step_errors),
                      e.demoted if e.implausible and not answer.implausible else "")
            for e in ranked if e.significant and e is not answer and id(e) not in tied]


def indistinguishable(answer: EffectEvidence, ranked: list[EffectEvidence], md: ModelData, run_window: slice,
                      evaluation: slice, noise: Mapping[str, float]) -> list[Lookalike]:
    """The significant candidates other than ``answer`` whose errors on the fit windows and on the
    held-out half both tie with its (:func:`errors_tie`), each with what would separate it from the
    answer; one the physics rules out (:attr:`EffectEvidence.implausible`) only beside an answer it rules out too.

    :param md: the base model's data (its series, substeps and compared steps are the candidates' too).
    :param run_window: the simulated window; ``evaluation`` the held-out half inside it.
    :param noise: each target sensor's noise level σ (its unit).
    """
    others = [e for e in ranked if e.significant and e is not answer and (answer.implausible or not e.implausible)
              and errors_tie(answer.fit_step_errors, e.fit_step_errors)
              and errors_tie(answer.evaluation_step_errors, e.evaluation_step_errors)]
    return [Lookalike(other, tuple(_would_separate(answer, other, md, run_window, evaluation, noise)))
            for other in others]


def _would_separate(answer: EffectEvidence, other: EffectEvidence, md: ModelData, run_window: slice,
                    evaluation: slice, noise: Mapping[str, float]) -> list[str]:
    if answer.model is None or other.model is None or answer.theta is None or other.theta is None:
        return []
    offset = evaluation.start - run_window.start
    found = []
    sensor = _missing_sensor(answer, other, md, run_window, offset)
    if sensor:
        found.append(sensor)
    operation = _missing_operation(answer, other, md, run_window, offset, noise)
    if operation:
        found.append(operation)
    return found or ["nothing the model can show: both predict every quantity and every tried operation alike"]


def _unmeasured_places(evidence: EffectEvidence, md: ModelData, run_window: slice, offset: int) -> dict:
    """(building node, input port) → what the fitted model delivers there on the evaluation half,
    for every input of a component that is neither a measuring device nor an effect, fed by no
    device and by nothing a device also reads: a physical place no sensor sees, named alike in
    every candidate's model (an effect spliced on a port changes what arrives downstream, not the names)."""
    model = evidence.model
    devices = set(model.targets) | set(model.boundary_inputs)
    effects = {iri for iri, c in model.components.items() if c.signature.kind == "effect"}
    measured = {(c.source, c.source_port) for c in model.connections if c.target in devices}
    outputs = ModelData(model, md.data, md.substeps, md.compared).simulate_all(run_window, evidence.theta[None, :]).outputs
    places = {}
    for c in model.connections:
        if c.target in devices | effects or c.source in devices or (c.source, c.source_port) in measured:
            continue
        component = model.components[c.target]
        unit = next((port.unit for port in component.model_class.inputs if port.name == c.target_port), "")
        places[(component.node, c.target_port)] = (outputs[(c.source, c.source_port)][0][offset:], unit)
    return places


def _missing_sensor(answer: EffectEvidence, other: EffectEvidence, md: ModelData, run_window: slice,
                    offset: int) -> str | None:
    """The unmeasured place where the two fitted models differ most, in sensor accuracies, as a
    sentence with the triples that would add its sensor; None below :data:`SEPARATING_ACCURACIES`."""
    ours = _unmeasured_places(answer, md, run_window, offset)
    theirs = _unmeasured_places(other, md, run_window, offset)
    best = None
    for key in sorted(ours.keys() & theirs.keys()):
        (values, unit), (others, _) = ours[key], theirs[key]
        if unit not in _SENSOR_OF_UNIT:
            continue
        difference = values - others
        finite = np.isfinite(difference)
        if not finite.any():
            continue
        rms = float(np.sqrt(np.mean(difference[finite] ** 2)))
        accuracy = INSTRUMENT_ACCURACY_FLOOR.get(unit, RELATIVE_ACCURACY_FLOOR * float(np.nanmean(np.abs(values))))
        if accuracy > 0 and (best is None or rms / accuracy > best[0]):
            best = (rms / accuracy, rms, unit, *key)
    if best is None or best[0] < SEPARATING_ACCURACIES:
        return None
    ratio, rms, unit, node, port = best
    what, sensor_class, property_class, qudt = _SENSOR_OF_UNIT[unit]
    name = f"{local_name(node)}_{port}_sensor"
    sensor = node[: len(node) - len(local_name(node))] + name  # in the namespace of the node it serves
    return (f"a {what} sensor for the {port.replace('_', ' ')} of {local_name(node)}: the two differ there by "
            f"{quantity_text(rms, unit)} RMS, {ratio:.0f}× a sensor's accuracy, and the graph has none. Add it, placed "
            f"just upstream of {local_name(node)} on the flow path: <{sensor}> a {sensor_class} ; saref:observes "
            f"[ a {property_class} ] ; saref:isMeasuredIn {qudt} ; gt:timeSeriesId \"{name}\" ; "
            f"fso:suppliesFluidTo <{node}> .")


def _missing_operation(answer: EffectEvidence, other: EffectEvidence, md: ModelData, run_window: slice,
                       offset: int, noise: Mapping[str, float]) -> str | None:
    """The boundary input held at another level (:data:`WHAT_IF_KELVIN`, :data:`WHAT_IF_SHARE`)
    under which the two fitted models' predictions at the existing sensors part most, in noise
    levels, beyond how far they part on the data; None when no level makes them differ by
    :data:`SEPARATING_ACCURACIES` noise levels."""
    def parting(data) -> float:
        predictions = [ModelData(e.model, data, md.substeps, md.compared).simulate_targets(run_window, e.theta[None, :])
                       for e in (answer, other)]
        ratios = []
        for node, sigma in noise.items():
            if node in predictions[0] and node in predictions[1] and sigma > 0:
                difference = predictions[0][node][0][offset:] - predictions[1][node][0][offset:]
                finite = difference[np.isfinite(difference)]
                if finite.size:
                    ratios.append((float(np.sqrt(np.mean(finite ** 2))) / sigma, node))
        return max(ratios, default=(0.0, ""))

    on_data, _ = parting(md.data)
    best = None
    for component in answer.model.boundary_inputs:
        node = md.node_of[component]
        series, unit = md.data.series[node], md.data.units[node]
        level = float(np.nanmedian(series[run_window]))
        levels = (level - WHAT_IF_KELVIN, level + WHAT_IF_KELVIN) if unit in ("degC", "K") else (
            level * (1 - WHAT_IF_SHARE), level * (1 + WHAT_IF_SHARE))
        for value in levels:
            if unit == "1":
                value = min(max(value, 0.0), 1.0)
            held = np.where(np.isfinite(series), value, np.nan)
            try:
                ratio, sensor = parting(replace(md.data, series={**md.data.series, node: held}))
            except (ValueError, FloatingPointError):  # a level the model cannot run at
                continue
            if np.isfinite(ratio) and (best is None or ratio > best[0]):
                best = (ratio, sensor, node, value, unit)
    if best is None or best[0] < SEPARATING_ACCURACIES or best[0] < 2.0 * on_data:
        return None
    ratio, sensor, node, value, unit = best
    return (f"operation the data lack: with {local_name(node)} held at {quantity_text(value, unit)} throughout, the "
            f"two would part at {local_name(sensor)} by {ratio:.1f}× its noise (on these data by {on_data:.1f}×): a day "
            "run so would tell them apart")
