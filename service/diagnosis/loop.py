"""The diagnosis loop: where the calibrated model fails and which physical effect is missing.

:func:`diagnose` calibrates the base model on the training window (point fit), evaluates it on the
test window and answers (docs/diagnosis.md): **compare** (RMSE, MAE, CV(RMSE), NMBE per target),
**where** (a sensor fails when its test RMSE exceeds ``failure_ratio`` × its noise level
:func:`~service.calibration.metrics.noise_level`; located on the flow path, in operating regimes and in time), **what is missing**
(the effect catalog refitted and ranked, :mod:`service.diagnosis.candidates`) and, when nothing is,
what the failing sensors' residual follows. The result is a :class:`~service.diagnosis.report.DiagnosisReport`,
also written to the store as triples. The method in full: ``docs/diagnosis.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from service.calibration.run import calibrate
from service.components.library import SignatureLibrary
from service.data.windows import Window
from service.diagnosis.candidates import rank_catalog, split_windows
from service.diagnosis.drift import drifting_components
from service.diagnosis.episodes import Episode, find_episodes
from service.diagnosis.localization import FailureLocation, FlowTopology, localize_failures
from service.diagnosis.ranking import MIN_TEST_IMPROVEMENT, EffectEvidence
from service.diagnosis.report import (
    FAILURE_RATIO,
    MIN_TEST_STEPS,
    DiagnosisReport,
    SensorVerdict,
    diagnosis_triples,
    fails_at,
    spans_a_regime,
)
from service.diagnosis.residual_dependence import Dependence, distinct_signals, residual_dependence, time_trend
from service.diagnosis.separation import indistinguishable, told_apart
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.graph.units import difference_label
from service.matching.signature import Signature
from service.model.assembled_model import AssembledModel

__all__ = ["diagnose", "MIN_TEST_STEPS"]


def diagnose(
    store: GraphStore,
    model_name: str,
    data_path: Path | str,
    *,
    train: Window,
    test: Window,
    seed: int = 0,
    substeps: int | None = None,
    library: dict[str, Signature] | None = None,
    failure_ratio: float = FAILURE_RATIO,
    refit_max_nfev: int = 30,
    workers: int | None = None,
    on_progress: Callable[[str], None] | None = None,
    rank_effects: bool = True,
    only_when: Sequence[str] = (),
    start_from: str | None = None,
) -> DiagnosisReport:
    """Calibrate on ``train``, compare on ``test``, locate the failures and rank the missing effects
    (``rank_effects=False``: compare and locate only, ``graphtwin compare``; the failing sensors'
    residual dependence is then always reported). ``only_when``: operating conditions, the targets
    compared only where all hold (:mod:`service.data.operating_filter`). ``start_from``: a model in the
    store whose latest calibration starts the base fit (:func:`service.calibration.run.calibrated_start`)."""
    say = on_progress or (lambda message: None)
    library = library or SignatureLibrary.load()
    base = calibrate(store, model_name, data_path, train=train, test=test, seed=seed, substeps=substeps,
                     only_when=only_when, min_test_steps=MIN_TEST_STEPS, start_from=start_from,
                     on_prepared=lambda: say("calibrating the base model"))
    md, model = base.model_data, base.model
    data = md.data
    test_slice = base.test
    if test_slice is None:
        raise ValueError("diagnose needs a test window")
    predicted = base.predictions["test"]
    observed = {node: np.where(np.isfinite(predicted[node]), values, np.nan)
                for node, values in md.observed(test_slice).items()}
    residuals = {node: observed[node] - predicted[node] for node in observed}
    sensors: dict[str, SensorVerdict] = {}
    for node, metrics in base.record.metrics["test"].items():
        sigma = metrics.noise  # noise_level of this residual, computed with the metrics
        sensors[node] = SensorVerdict(
            rmse=metrics.rmse, mae=metrics.mae, cv_rmse_percent=metrics.cv_rmse_percent,
            nmbe_percent=metrics.nmbe_percent, r2=metrics.r2, unit=md.units[node], noise=sigma,
            fails=fails_at(metrics.rmse, sigma, failure_ratio), logged_unit=md.data.source_units.get(node, ""),
        )
    topology = FlowTopology.from_store(store, model_name)
    carries = _carried_down(residuals, md.units, {node: s.noise for node, s in sensors.items()}, failure_ratio)

    def locate(located: Mapping[str, bool]) -> list[FailureLocation]:
        """The failures on the flow path of the target sensors ``located`` marks (node → True)."""
        matches = {md.node_of[c]: True for c in model.boundary_inputs} | {n: not bad for n, bad in located.items()}
        inputs = [md.node_of[c] for c in model.boundary_inputs]
        return localize_failures(topology, matches, inputs + [md.node_of[c] for c in model.targets],
                                 carries=carries, inputs=inputs)

    failing = [n for n, s in sensors.items() if s.fails]
    # a drift of the parameters of the components suspected for the most-failing sensor competes too
    drift = {"drifting": drifting_components(model, locate({n: s.fails for n, s in sensors.items()}),
                                             max(failing, key=lambda n: sensors[n].rmse_over_noise)),
             "failing_noise": {n: sensors[n].noise for n in failing}} if failing and rank_effects else {}
    ranked, skipped = (rank_catalog(store, model_name, library, base, seed=seed, refit_max_nfev=refit_max_nfev,
                                    workers=workers, say=say, **drift)
                       if rank_effects else ([], []))
    answer = next((e for e in ranked if e.significant), None)
    lookalikes, others = [], []
    if answer is not None:  # one story: where the missing effect shows, a failure is located
        reached = _sensors_reached(answer, model)
        sensors = {node: replace(verdict, shows_missing_effect=node in reached
                                 and answer.error_removed_at(node) >= MIN_TEST_IMPROVEMENT)
                   for node, verdict in sensors.items()}
        say("telling the answer from its look-alikes")
        _, run_window, evaluation = split_windows(base.train, test_slice)
        lookalikes = indistinguishable(answer, ranked, md, run_window, evaluation,
                                       {node: verdict.noise for node, verdict in sensors.items()})
        others = told_apart(answer, ranked, lookalikes)
    say("locating the failures")
    localization = locate({n: s.located for n, s in sensors.items()})
    regimes = _regimes_with_worst(base.regimes.rows(), sensors, test_slice.stop - test_slice.start)
    episodes: dict[str, list[Episode]] = {}
    for node in observed:
        found = find_episodes(data.timestamps[test_slice], observed[node], residual=residuals[node],
                              min_deviation=failure_ratio * sensors[node].noise, unit=difference_label(md.units[node]),
                              logged_unit=sensors[node].logged_unit)
        if found:
            episodes[node] = found

    dependence = (_residual_dependence(base, failing, residuals)
                  if failing and not any(e.significant for e in ranked) else {})
    trends = {node: trend for node in dependence
              if (trend := time_trend(residuals[node], data.timestamps[test_slice])) is not None}

    report = DiagnosisReport(
        model_name=model_name, run_id=base.record.run_id, sensors=sensors, localization=localization,
        regimes=regimes, regime_rule_accuracy=base.regimes.rule_accuracy, episodes=episodes,
        effects=ranked, not_applicable=skipped, residual_dependence=dependence, step_s=data.step_s,
        base_test_prediction=predicted, effects_tested=rank_effects, test_timestamps=data.timestamps[test_slice],
        test_observed=observed, failure_ratio=failure_ratio,
        data_warnings=list(base.record.diagnostics.warnings),
        indistinguishable=lookalikes, told_apart=others, residual_trend=trends,
    )
    store.write_graph(store.run_graph(f"{base.record.run_id}-diagnosis"), diagnosis_triples(report))
    return report


def _sensors_reached(effect: EffectEvidence, base: AssembledModel) -> set[str]:
    """The sensors (nodes) ``effect`` can move: the targets downstream of its components in its model,
    or of the component whose parameter it drifts. A sensor it cannot reach that its refit improves was
    mended by the base parameters the refit frees (a fan's unidentified curve), not by the effect."""
    model = effect.model
    if model is None:  # not kept (evidence read back): every sensor, as before
        return {base.measurement(c).node for c in base.targets}
    sources = (set(model.components) - set(base.components)
               or {drift.parameter_key.rpartition("#")[0] for drift in model.drifts})
    return {model.measurement(c).node for c in model.targets_reached_from(sources)}


def _regimes_with_worst(regimes: list[dict], sensors: Mapping[str, SensorVerdict], test_steps: int) -> list[dict]:
    """The calibration's regime rows, each with ``"worst"``: True for the one with the largest mean
    RMSE / noise over its sensors among those holding at least :data:`MIN_TEST_STEPS` of the
    ``test_steps`` (an RMSE over a step or two is a spike's, not a regime's; all when none does; none
    when no regime with a share has a finite one)."""
    scaled = [np.array([r["rmse"][k] / sensors[k].noise for k in r["rmse"]]) for r in regimes]
    scaled = [float(np.nanmean(s)) if r["share"] > 0 and np.isfinite(s).any() else np.nan
              for r, s in zip(regimes, scaled)]
    held = [spans_a_regime(r, test_steps) for r in regimes]
    if any(h and np.isfinite(v) for h, v in zip(held, scaled)):
        scaled = [v if h else np.nan for h, v in zip(held, scaled)]
    for row in regimes:
        row["worst"] = False
    if np.isfinite(scaled).any():
        regimes[int(np.nanargmax(scaled))]["worst"] = True
    return regimes


def _residual_dependence(base, failing: list[str], residuals: Mapping[str, np.ndarray]) -> dict[str, list[Dependence]]:
    """Per failing sensor, the (up to three) ranked signals its test residual follows: the measured
    series and the model's outputs, except the sensor's own; a signal that is one before it under a
    second name (|ρ| ≥ :data:`SAME_SIGNAL_CORRELATION`: a measured input and the model's copy of it, a
    fan's air flow and its speed) is left out, the measured series kept first."""
    md = base.model_data
    data, train_slice, test_slice = md.data, base.train, base.test
    window = slice(train_slice.start, test_slice.stop) if test_slice.start >= train_slice.start else test_slice
    everything = md.simulate_all(window, base.theta)
    offset = test_slice.start - window.start
    signals = {f"measured {local_name(n)}": data.series[n][test_slice] for n in data.series}
    for (component, port), values in everything.outputs.items():
        signals[f"model {local_name(component)}.{port}"] = values[0][offset:]
    signals = distinct_signals(signals)
    dependence = {}
    for node in failing:
        ranked = residual_dependence(residuals[node], {k: v for k, v in signals.items() if local_name(node) not in k})
        dependence[node] = [d for d in ranked[:3] if d.skipped_reason is None]
    return dependence


def _carried_down(residuals: Mapping[str, np.ndarray], units: Mapping[str, str], noise: Mapping[str, float],
                  failure_ratio: float) -> Callable[[str, str], bool]:
    """``carries(u, f)`` for :func:`localize_failures`: the failure at ``f`` is the one the failing
    sensor ``u`` upstream carries down unless both measure in one unit and what ``f``'s residual
    adds to ``u``'s, ``r_f − r_u``, has an RMS above ``failure_ratio`` × √(σ_f² + σ_u²) (their noise
    levels): then the error grows between them. Sensors of different units cannot be told apart
    that way, and neither can two without a common measured step: carried."""
    def carries(upstream: str, failing: str) -> bool:
        if upstream not in residuals or units.get(upstream) != units.get(failing):
            return True
        added = residuals[failing] - residuals[upstream]
        added = added[np.isfinite(added)]
        if not added.size:
            return True
        return float(np.sqrt(np.mean(added**2))) <= failure_ratio * float(np.hypot(noise[failing], noise[upstream]))
    return carries
