"""What a diagnosis found: :class:`DiagnosisReport`, its per-sensor verdicts, its one-sentence summary
and its triples.

:meth:`DiagnosisReport.to_dict` is the CLI's ``--json`` contract and the HTTP job result;
:func:`diagnosis_triples` writes the report as a ``gt:DiagnosisRun`` with its ranked candidates and
failure locations (the operating regimes and their error are the base calibration's). Errors are in
each sensor's unit; ``cv_rmse`` and ``nmbe`` in percent. The method: ``docs/diagnosis.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyoxigraph as ox

from service.calibration.triples import run_iri
from service.diagnosis.drift import DriftEvidence
from service.diagnosis.episodes import Episode
from service.diagnosis.localization import FailureLocation
from service.diagnosis.ranking import EffectEvidence
from service.diagnosis.residual_dependence import Dependence, TimeTrend
from service.diagnosis.separation import Lookalike, ToldApart
from service.graph.namespaces import DCTERMS, GT, PROV, RDF, RDFS, XSD, distinct_local_names, local_name
from service.graph.units import difference_label

__all__ = ["FAILURE_RATIO", "MIN_TEST_STEPS", "fails_at", "spans_a_regime",
           "SensorVerdict", "DiagnosisReport", "diagnosis_triples"]

#: A sensor fails where its test RMSE exceeds this multiple of its noise σ (``docs/diagnosis.md``).
FAILURE_RATIO = 2.0


def fails_at(rmse: float, noise: float, failure_ratio: float = FAILURE_RATIO) -> bool:
    """Whether a sensor whose test RMSE is ``rmse`` fails against its noise σ ``noise`` (same unit):
    RMSE > failure_ratio · σ."""
    return bool(rmse > failure_ratio * noise)


#: Fewer test steps than this give no verdict (diagnose refuses the window before calibrating): the
#: noise level comes from second differences and the effects are judged on the window's second half;
#: a regime over fewer is a spike's, not one to name worst.
MIN_TEST_STEPS = 12


def spans_a_regime(row: dict, test_steps: int) -> bool:
    """Whether a regime row (its ``share`` of the ``test_steps``) holds :data:`MIN_TEST_STEPS` of them:
    an RMSE over fewer is a spike's, not a regime's to name worst."""
    return row["share"] * test_steps >= MIN_TEST_STEPS


@dataclass(frozen=True, kw_only=True)
class SensorVerdict:
    """One target sensor on the test window: its errors (``rmse``, ``mae`` in ``unit``; the
    coefficient of variation of the RMSE and the normalised mean bias error in percent; R²), its
    noise level σ (``unit``), whether the model fails there (RMSE above the failure ratio × σ) and
    whether the answer's missing effect shows there (it removes at least
    :data:`~service.diagnosis.ranking.MIN_TEST_IMPROVEMENT` of the sensor's held-out error): either
    locates a failure at the sensor."""

    rmse: float
    mae: float
    cv_rmse_percent: float
    nmbe_percent: float
    r2: float
    unit: str
    noise: float
    fails: bool
    shows_missing_effect: bool = False
    logged_unit: str = ""  # the unit its column was logged in, where it is not ``unit`` (°F for a port in °C)

    @property
    def located(self) -> bool:
        return self.fails or self.shows_missing_effect

    @property
    def rmse_over_noise(self) -> float:
        return self.rmse / self.noise

    def to_dict(self) -> dict:
        return {"rmse": self.rmse, "mae": self.mae, "cv_rmse": self.cv_rmse_percent, "nmbe": self.nmbe_percent,
                "r2": self.r2, "unit": self.unit, "noise": self.noise, "rmse_over_noise": self.rmse_over_noise,
                "fails": self.fails, "shows_missing_effect": self.shows_missing_effect,
                **({"logged_unit": self.logged_unit} if self.logged_unit else {})}


@dataclass(frozen=True, kw_only=True)
class DiagnosisReport:
    """Everything ``diagnose`` found (see :meth:`to_dict` for the CLI contract).

    ``regimes``: the calibration's rows (``{"regime", "rule", "share", "rmse": {sensor: value}}``)
    with ``"worst"`` marking the one with the largest mean RMSE / noise (of those spanning at least
    ``MIN_TEST_STEPS`` steps); ``residual_dependence``: per
    failing sensor, the (up to three) signals its residual follows, described with ``step_s`` (the
    data's sampling interval, s), and ``residual_trend`` its trend in time; ``effects_tested``: False
    for ``graphtwin compare``.
    """

    model_name: str
    run_id: str
    sensors: dict[str, SensorVerdict]
    localization: list[FailureLocation]
    regimes: list[dict]
    regime_rule_accuracy: float
    episodes: dict[str, list[Episode]]
    effects: list[EffectEvidence]
    not_applicable: list[str]
    residual_dependence: dict[str, list[Dependence]] = field(default_factory=dict)
    step_s: float | None = None
    effects_tested: bool = True
    base_test_prediction: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    test_timestamps: np.ndarray | None = field(default=None, repr=False)
    test_observed: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    failure_ratio: float = FAILURE_RATIO
    data_warnings: list[str] = field(default_factory=list)  # reading the data and assembling: frozen points, gaps
    indistinguishable: list[Lookalike] = field(default_factory=list)  # significant, tied with the answer
    told_apart: list[ToldApart] = field(default_factory=list)  # significant, not tied: why not the answer
    residual_trend: dict[str, TimeTrend] = field(default_factory=dict)

    @property
    def significant(self) -> list[EffectEvidence]:
        return [e for e in self.effects if e.significant]

    @property
    def answer(self) -> EffectEvidence | None:
        """The missing effect: the first significant candidate of the ranking, or None."""
        return next(iter(self.significant), None)

    @property
    def failing_sensors(self) -> list[str]:
        return [node for node, verdict in self.sensors.items() if verdict.fails]

    @property
    def summary(self) -> str:
        """One sentence: the missing effect and why, or that nothing is missing, or where it fails."""
        failing = self.failing_sensors
        if not self.effects_tested:
            if not failing:
                return "The model matches every sensor within its noise."
            return (f"The model fails at {', '.join(local_name(n) for n in failing)}: see localization, regimes and "
                    "episodes for where, residual_dependence for what the residual follows, and graphtwin diagnose "
                    f"for which effect is missing. {self.residual_structure()}")
        if not self.significant:
            if not failing:
                return "The model matches every sensor within its noise; nothing significant is missing."
            return (f"The model fails at {', '.join(local_name(n) for n in failing)}, but no effect in the catalog "
                    f"and no drift of a parameter explains it significantly. {self.residual_structure()}")
        best = self.answer
        explanation = best.explanation[:1].upper() + best.explanation[1:]
        sentence = f"Missing: {best.label} at {local_name(best.node)}. {explanation}."
        if self.indistinguishable:
            sentence += (" Indistinguishable on these data: "
                         + "; ".join(f"{e.effect.label} at {local_name(e.effect.node)}" for e in self.indistinguishable)
                         + " (their per-step errors tie with the answer's within two standard errors on the fit "
                         "windows and on the held-out half, whatever their ΔBICs; see indistinguishable for what "
                         "would separate them).")
        return sentence

    def residual_structure(self) -> str:
        """The most-failing sensor's residual in words: its trend in time, the operating regime where
        its error is largest, and the signal it follows most (what of these the report holds)."""
        failing = self.failing_sensors
        if not failing:
            return ""
        node = max(failing, key=lambda n: self.sensors[n].rmse_over_noise)
        verdict = self.sensors[node]
        unit = difference_label(verdict.unit)
        parts = []
        if node in self.residual_trend:
            parts.append(self.residual_trend[node].describe(unit))
        regimes = [r for r in self.regimes if r["share"] > 0 and np.isfinite(r["rmse"].get(node, np.nan))]
        steps = len(self.test_timestamps) if self.test_timestamps is not None else 0
        regimes = [r for r in regimes if spans_a_regime(r, steps)] or regimes  # as the worst regime's
        if len(regimes) > 1:
            worst = max(regimes, key=lambda r: r["rmse"][node])
            parts.append(f"its error is largest where {worst['rule']} (RMSE {worst['rmse'][node]:.3g} {unit} over "
                         f"{100 * worst['share']:.0f} % of the test window)")
        if self.residual_dependence.get(node):
            parts.append(self.residual_dependence[node][0].describe(self.step_s).replace("the residual", "it", 1))
        described = "; ".join(parts) or "its residual has no structure the report can name"
        return (f"At {local_name(node)}, the worst (RMSE {verdict.rmse:.3g} {unit}, {verdict.rmse_over_noise:.1f}× its "
                f"noise): {described}.")

    def to_dict(self) -> dict:
        return {
            "model": self.model_name, "run": self.run_id, "summary": self.summary,
            "sensors": {node: verdict.to_dict() for node, verdict in self.sensors.items()},
            "localization": [dict(location.to_dict(), text=location.describe()) for location in self.localization],
            "regimes": self.regimes, "regime_rule_accuracy": self.regime_rule_accuracy,
            "episodes": {node: [e.to_dict() for e in found] for node, found in self.episodes.items()},
            "effects": [e.to_dict() for e in self.effects],
            "answer": self.answer.to_dict() if self.answer is not None else None,
            "indistinguishable": [lookalike.to_dict() for lookalike in self.indistinguishable],
            "told_apart": [other.to_dict() for other in self.told_apart],
            "effects_tested": self.effects_tested,
            "nothing_significant_missing": not self.significant if self.effects_tested else None,
            "not_applicable": self.not_applicable,
            "residual_dependence": {
                node: {"signals": [d.to_dict() | {"text": d.describe(self.step_s)} for d in signals]}
                for node, signals in self.residual_dependence.items()},
            "residual_trend": {node: trend.to_dict()
                               | {"text": trend.describe(difference_label(self.sensors[node].unit))}
                               for node, trend in self.residual_trend.items()},
            "data_warnings": self.data_warnings,
        }


def diagnosis_triples(report: DiagnosisReport) -> list[ox.Triple]:
    """The diagnosis as triples: a gt:DiagnosisRun with its ranked candidates and failure locations
    (the operating regimes and their error are the base calibration's)."""
    run = ox.NamedNode(run_iri(report.run_id).value + "/diagnosis")
    calibration = run_iri(report.run_id)
    dbl = lambda v: ox.Literal(repr(float(v)), datatype=XSD.double)  # noqa: E731
    t = [ox.Triple(run, RDF.type, GT.DiagnosisRun), ox.Triple(run, RDF.type, PROV.Activity),
         ox.Triple(run, GT.basedOnCalibration, calibration), ox.Triple(run, GT.forModel, ox.Literal(report.model_name)),
         ox.Triple(run, RDFS.comment, ox.Literal(report.summary))]
    t += [ox.Triple(run, GT.notApplicable, ox.Literal(reason)) for reason in report.not_applicable]
    node_name = distinct_local_names(item.node for item in report.effects)

    def candidate_node(item: EffectEvidence) -> ox.NamedNode:
        return ox.NamedNode(f"{run.value}/candidate/{item.effect}/{node_name[item.node]}")

    for rank, item in enumerate(report.effects, start=1):
        node = candidate_node(item)
        t += [ox.Triple(node, RDF.type, GT.EffectCandidate), ox.Triple(node, PROV.wasGeneratedBy, run),
              ox.Triple(node, GT.candidateEffect, ox.NamedNode(item.effect_iri)),
              ox.Triple(node, GT.onNode, ox.NamedNode(item.node)),
              ox.Triple(node, GT.rank, ox.Literal(str(rank), datatype=XSD.integer)),
              ox.Triple(node, GT.significant, ox.Literal("true" if item.significant else "false", datatype=XSD.boolean)),
              ox.Triple(node, GT.explanation, ox.Literal(item.explanation))]
        if item is report.answer:
            t.append(ox.Triple(run, GT.answer, node))
        if isinstance(item, DriftEvidence):  # not in the signature library: named here
            drift = ox.NamedNode(item.effect_iri)
            t += [ox.Triple(drift, RDF.type, GT.ParameterDrift), ox.Triple(drift, DCTERMS.identifier, ox.Literal(item.effect)),
                  ox.Triple(drift, RDFS.label, ox.Literal(item.label))]
        tied = next((lookalike for lookalike in report.indistinguishable if lookalike.effect is item), None)
        if tied is not None:
            t.append(ox.Triple(node, GT.indistinguishableFrom, candidate_node(report.answer)))
            t += [ox.Triple(node, GT.wouldSeparate, ox.Literal(text)) for text in tied.would_separate]
        apart = next((other for other in report.told_apart if other.effect is item), None)
        if apart is not None:
            t.append(ox.Triple(node, GT.toldApartFrom, candidate_node(report.answer)))
            distances = ((GT.fitDistance, apart.fit_z), (GT.heldOutDistance, apart.held_out_z))
            t += [ox.Triple(node, predicate, dbl(z)) for predicate, z in distances if z is not None and np.isfinite(z)]
            if apart.ruled_out:
                t.append(ox.Triple(node, RDFS.comment, ox.Literal(f"ruled out by the physics: {apart.ruled_out}")))
        for predicate, value in ((GT.scoreStatistic, item.score.statistic), (GT.pValue, item.score.p_value),
                                 (GT.deltaBic, item.delta_bic), (GT.testImprovement, item.test_improvement)):
            if np.isfinite(value):
                t.append(ox.Triple(node, predicate, dbl(value)))
    for index, location in enumerate(report.localization):
        node = ox.NamedNode(f"{run.value}/location/{index}")
        t += [ox.Triple(node, RDF.type, GT.FailureLocation), ox.Triple(node, PROV.wasGeneratedBy, run),
              ox.Triple(node, GT.failingSensor, ox.NamedNode(location.failing_sensor)),
              ox.Triple(node, RDFS.comment, ox.Literal(location.describe()))]
        if location.matching_sensor:
            upstream = GT.failingUpstreamSensor if location.upstream_fails else GT.matchingSensor
            t.append(ox.Triple(node, upstream, ox.NamedNode(location.matching_sensor)))
        if location.through_controller_of:
            t.append(ox.Triple(node, GT.throughControllerOf, ox.NamedNode(location.through_controller_of)))
        t += [ox.Triple(node, GT.suspect, ox.NamedNode(c)) for c in location.components]
    return t
