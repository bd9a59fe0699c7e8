"""Which effect of the catalog is missing: every applicable (effect, node) candidate, and a drift of a
failing component's parameters (:mod:`service.diagnosis.drift`), refitted and judged.

Each candidate is fitted on the training window plus the first half of the test window and judged on
the second half (:func:`split_windows`), against the base model refitted on the same windows or as
trained: score test at the null, refit (present throughout, or appearing in the test window),
ΔBIC, test-window error removed (:mod:`service.diagnosis.ranking`), and one sentence of explanation.
Candidates are evaluated side by side, their simulations shared
(:mod:`service.diagnosis.shared_runs`). The method: ``docs/diagnosis.md``, "What is missing".
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import replace
from multiprocessing import get_context
from queue import Empty
from typing import NamedTuple

import numpy as np

from service.calibration.lockstep import with_prefetched_rows
from service.calibration.model_data import ModelData
from service.data.model_series import with_series_of
from service.diagnosis.drift import (
    DriftEvidence,
    drift_beyond_range,
    drift_candidates,
    drift_fields,
    drift_sentence,
    step_onset,
)
from service.diagnosis.plausibility import bound_note, demotion_reasons, flow_share_text, surroundings_caution
from service.diagnosis.ranking import (
    EffectEvidence,
    delta_bic,
    per_target_rss,
    rank_evidence,
    score_ensemble,
    score_test,
    step_errors,
    target_rows,
    weighted_test_error,
)
from service.diagnosis.refits import (
    REFIT_CONTINUATIONS,
    CandidateJob,
    Fit,
    fit_of,
    fit_onset,
    host_columns,
    mean_squares,
    null_values,
    probe_ensemble,
    probe_start,
    refit_calibrator,
    sample_fractions,
)
from service.diagnosis.shared_runs import OwnRuns, SharedRuns, shared_model
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.graph.units import unit_label
from service.matching.matcher import match_signature
from service.matching.nearest_miss import nearest_miss
from service.matching.signature import Signature
from service.model.assembled_model import AssembledModel
from service.model.assembly import assemble
from service.model.effect_splicing import EffectRequest, recorded_effects
from service.runtime import exit_with_parent, usable_cpu_count

__all__ = ["Candidate", "effect_candidates", "split_windows", "rank_catalog"]


class Candidate(NamedTuple):
    """An effect signature at one building node, and the model assembled with it."""

    signature: Signature
    node: str
    model: AssembledModel


def effect_candidates(store: GraphStore, model_name: str,
                      library: dict[str, Signature]) -> tuple[list[Candidate], list[str]]:
    """A :class:`Candidate` for every applicable pair the model does not record already and no
    effect it yields to (``yields_to``) applies at; and the reasons the others do not apply."""
    dataset = store.matching_dataset(model_name)
    applied = set(recorded_effects(store, model_name, library))
    candidates, skipped = [], []
    for signature in sorted((s for s in library.values() if s.kind == "effect"), key=lambda s: s.id):
        nodes = sorted({m[signature.splice.node] for m in match_signature(store, signature, default_graph=dataset)
                        if m.get(signature.splice.node)})
        if not nodes:
            why = nearest_miss(store, signature, default_graph=dataset)
            skipped.append(f"{signature.id}: its pattern ({signature.file_name}) matches nowhere: {why}")
        for node in nodes:
            if EffectRequest(signature.id, node) in applied:
                skipped.append(f"{signature.id} at {local_name(node)}: already in the model (gt:hasEffect)")
                continue
            try:
                model = assemble(store, model_name, library=library, extra_effects=[EffectRequest(signature.id, node)])
            except ValueError as exc:
                reason = str(exc).splitlines()[0].removeprefix(f"effect {signature.id} at {node}: ")
                skipped.append(f"{signature.id} at {local_name(node)}: {reason}")
                continue
            candidates.append(Candidate(signature, node, model))
    present = {(c.signature.id, c.node) for c in candidates} | {(r.effect, r.node) for r in applied}
    kept = []
    for candidate in candidates:
        specific = next((o for o in candidate.signature.yields_to if (o, candidate.node) in present), None)
        if specific is None:
            kept.append(candidate)
        else:
            skipped.append(f"{candidate.signature.id} at {local_name(candidate.node)}: {specific} applies there, "
                           f"which it yields to (yields_to in {candidate.signature.file_name})")
    return kept, skipped


def split_windows(train: slice, test: slice) -> tuple[list[slice], slice, slice]:
    """(fit windows, simulated window, evaluation window) of the effect comparison: fitted on the
    training window and the first half of the test window, judged on the second half, predicted as
    the continuation of the run from the training start when the test follows the training, else of
    a run over the whole test window. Steps between a training window and a later test window are
    simulated through, not fitted."""
    middle = test.start + (test.stop - test.start) // 2
    evaluation = slice(middle, test.stop)
    if train.start <= test.start <= train.stop:
        return [slice(train.start, middle)], slice(train.start, test.stop), evaluation
    fit = [train, slice(test.start, middle)]
    return fit, (slice(train.start, test.stop) if test.start > train.stop else test), evaluation


def _predict_evaluation(md: ModelData, run_window: slice, evaluation: slice,
                        *thetas: np.ndarray) -> list[dict[str, np.ndarray]]:
    """Each θ's prediction of the evaluation window (target → ndarray[n_steps]), run from
    ``run_window``'s start, all in one simulate call."""
    return _evaluation_rows(md.simulate_targets(run_window, np.vstack(thetas)), run_window, evaluation)


def _evaluation_rows(runs: dict[str, np.ndarray], run_window: slice, evaluation: slice) -> list[dict[str, np.ndarray]]:
    """Each member's part of ``runs`` (target → ndarray[n_members, n_steps] over ``run_window``) in
    the evaluation window."""
    offset = evaluation.start - run_window.start
    return [{k: v[member][offset:] for k, v in runs.items()} for member in range(len(next(iter(runs.values()))))]


def _estimate_text(name: str, value: float, standard_error: float, spec) -> str:
    """``name = value ± se`` (with :func:`_bound_note`), or, where the standard error spans the
    prior range or is not finite, that the data do not identify it."""
    label = unit_label(spec.unit)
    unit = f" {label}" if label else ""
    if not np.isfinite(standard_error) or standard_error > spec.upper - spec.lower:
        return (f"{name} = {value:.3g}{unit}, not identified (the data leave it anywhere in "
                f"[{spec.lower:g}, {spec.upper:g}]{unit})")
    return f"{name} = {value:.3g} ± {standard_error:.2g}{unit}" + bound_note(value, spec)


def _evaluate_candidate(job: CandidateJob, runs: OwnRuns | None = None) -> EffectEvidence:
    """Score test, refit under both hypotheses, ΔBIC and the evaluation half's error before and after;
    ``runs``: where its simulations run (default: its own model's simulator, :class:`OwnRuns`)."""
    runs = runs or OwnRuns(job.data, job.substeps, job.compared)
    md = runs.data_for(job.model)
    refs = job.model.estimated_parameters
    effect_columns = [j for j, r in enumerate(refs) if r.key not in job.base_theta]
    theta0 = np.array([job.base_theta.get(r.key, np.nan) for r in refs])
    theta0[effect_columns] = null_values(refs, effect_columns)
    theta_train = np.array([job.train_theta.get(r.key, theta0[j]) for j, r in enumerate(refs)])
    if job.drift_onsets:  # a step drift: its onset picked by the fit, on the grid
        job = replace(job, model=step_onset(md, job.fit_windows, [theta0, theta_train], job.drift_onsets,
                                            job.target_scales))
        md = runs.data_for(job.model)
    appearing = []  # the fits of a fault appearing in the test window, independent of the fit throughout
    if job.onset_windows is not None and effect_columns and job.signature is not None and job.signature.can_appear:
        appearing.append(("appearing in the test window",
                          lambda data: fit_onset(data, job, theta_train, effect_columns)))
        host = host_columns(job)
        if host:  # an unexercised host may hide what the effect does: fit it with the effect too
            appearing.append(("appearing in the test window, its host refitted",
                              lambda data: fit_onset(data, job, theta_train, effect_columns, host)))

    def present_throughout():
        """(the fit windows' problem, the score test at the null, the fit of the effect present throughout)."""
        problem = md.problem(job.fit_windows, default=theta0, target_scales=job.target_scales)
        calibrator = refit_calibrator(job.seed, job.refit_max_nfev)
        # the score test's members, the probe's grid and the refit's screen in one simulate call
        problem = with_prefetched_rows(problem, score_ensemble(problem, theta0),
                                       probe_ensemble(problem, theta0, effect_columns, theta_train),
                                       problem.from_unit(calibrator.screen_points(problem)))
        score = score_test(problem, theta0, effect_columns,
                           sample_fractions=[job.sample_fractions[k] for k in problem.target_keys])
        problem = replace(problem, default=probe_start(problem, theta0, effect_columns, theta_train))
        calibrator.fit(problem)
        return problem, score, fit_of(calibrator, calibrator.theta_, calibrator.standard_errors_, job.target_scales,
                                      len(effect_columns) + (1 if job.drift_onsets else 0))

    (problem, score, throughout), onsets = runs.alongside(job.model, present_throughout, [f for _, f in appearing])
    fits = {"present throughout": throughout} | {name: fit for (name, _), fit in zip(appearing, onsets)}
    keys = problem.target_keys
    counts = np.array([problem.masks[k].sum() for k in keys], dtype=float)

    def bic_against(before: dict[str, float], after: dict[str, float], fractions: dict[str, float],
                    freed: int) -> float:
        return delta_bic([before[k] * c for k, c in zip(keys, counts)], [after[k] * c for k, c in zip(keys, counts)],
                         counts * np.array([fractions[k] for k in keys]), freed)

    # the hypotheses compared by their ΔBIC against one base, each counting what it frees; n_eff from
    # the hypothesis's own residuals (the base's hold the very misfit the effect explains: on a
    # FLEXLAB fault day their ρ₁ ≈ 0.98 left ~3 effective observations per sensor)
    def bic_of(fit: Fit) -> float:
        return bic_against(job.base_mean_squares, fit.mean_squares, fit.sample_fractions, fit.freed)

    onset = min(fits, key=lambda name: bic_of(fits[name]))
    theta, standard_errors, fit_mean_squares, fractions, freed, converged, fit_step_errors = fits[onset]
    # what the refit gains with the base parameters alone (the effect set back to its null) is the
    # base model's, not the effect's: "before" is the better of the base refit and that
    theta_null = theta.copy()
    theta_null[effect_columns] = null_values(refs, effect_columns)
    predicted = md.simulate_targets(job.run_window, np.vstack([theta_null, theta]))
    fit = job.fit_windows[0]
    if len(job.fit_windows) == 1 and fit.start == job.run_window.start and fit.stop <= job.run_window.stop:
        # a run is the same over its window's first part as over that part alone (tested)
        null_outputs = {key: values[:1, :fit.stop - fit.start] for key, values in predicted.items()}
    else:
        null_outputs = problem.run(theta_null[None, :])
    null_residuals = problem.weighted_residuals(null_outputs)[0]
    null_mean_squares = dict(zip(keys, per_target_rss(null_residuals, target_rows(problem)) / counts))
    base_mean_squares = min((job.base_mean_squares, null_mean_squares),
                            key=lambda before: bic_against(job.base_mean_squares, before, job.sample_fractions, 0))
    observed = md.observed(job.evaluation)
    null, after = _evaluation_rows(predicted, job.run_window, job.evaluation)
    before = min((job.base_evaluation_prediction, null),
                 key=lambda prediction: weighted_test_error(observed, prediction, job.target_scales))
    effect, effect_iri, label = job.identity()
    drifts = job.model.drifts
    described = drift_fields(job.model, job.data.timestamps, job.data.step_s)
    evidence = (DriftEvidence if drifts else EffectEvidence)(
        effect=effect, effect_iri=effect_iri, node=job.node, label=label,
        parameter_names=tuple(refs[j].name for j in effect_columns), score=score,
        delta_bic=bic_against(base_mean_squares, fit_mean_squares, fractions, freed), freed_parameters=freed,
        estimates={refs[j].name: float(theta[j]) for j in effect_columns},
        standard_errors={refs[j].name: float(standard_errors[j]) for j in effect_columns}, **described,
    )
    before_error = weighted_test_error(observed, before, job.target_scales)
    evidence.evaluation_step_errors = step_errors(observed, after, job.target_scales)
    after_error = float(evidence.evaluation_step_errors.sum())
    evidence.theta = theta
    evidence.appears_in_test_window = onset != "present throughout"
    evidence.fit_step_errors = fit_step_errors
    evidence.test_improvement = 1.0 - after_error / before_error if before_error > 0 else 0.0
    for node, values in observed.items():
        mask = np.isfinite(values)
        evidence.rmse_before[node] = float(np.sqrt(np.mean((values[mask] - before[node][mask]) ** 2)))
        evidence.rmse_after[node] = float(np.sqrt(np.mean((values[mask] - after[node][mask]) ** 2)))
    physics = "; ".join(filter(None, [
        demotion_reasons(job.model, job.node, theta, effect_columns),
        drift_beyond_range(job.model, theta, job.data.step_s, job.evaluation.stop - 1) if drifts else ""]))
    evidence.implausible = bool(physics)
    stopped = "" if converged else (f"its refit did not converge in {1 + REFIT_CONTINUATIONS} runs of "
                                    f"{job.refit_max_nfev} evaluations")
    evidence.demoted = "; ".join(filter(None, [physics, stopped]))
    demotion = f"; ranked below the plausible effects: {evidence.demoted}" if evidence.demoted else ""
    if drifts:
        lead = drift_sentence(job.model, theta, standard_errors, job.data.timestamps, job.data.step_s,
                              job.evaluation.stop - 1)
        picked = "; its onset picked by the fit (a 6-hour grid, then the data steps around the best)" if job.drift_onsets else ""
        _explain(evidence, observed, null, after, "the drift", f"fitted with the base parameters{picked}{demotion}",
                 lead, job.target_scales)
        evidence.model = job.model  # with the onset the fit picked
        return evidence
    estimates = "; ".join(filter(None, [
        *(_estimate_text(refs[j].name, theta[j], standard_errors[j], refs[j].spec) for j in effect_columns),
        flow_share_text(job.model, job.node, theta, standard_errors, effect_columns),
        surroundings_caution(job.model, theta, standard_errors, effect_columns, job.data)]))
    _explain(evidence, observed, null, after, f"{effect} at {local_name(job.node)}",
             f"{estimates}; fitted as an effect {onset}{demotion}", "", job.target_scales)
    return evidence


def _explain(evidence: EffectEvidence, observed: dict[str, np.ndarray], null: dict[str, np.ndarray],
             after: dict[str, np.ndarray], what: str, fit_text: str, lead: str, scales: Mapping[str, float]) -> None:
    """Set the evidence's sentence: ``lead`` (what a drift does), the sensor
    where the effect itself (its prediction ``after`` against the same parameters with the effect at
    its null) removes the most scaled error, how its residual r follows what ``what`` adds, c — the
    cosine Σr·c / √(Σr²·Σc²), its mean included (a correlation would miss an effect that shifts a
    reading by a constant, as a heat gain at a constant flow does) — and ``fit_text``."""
    def mean_square(prediction: dict[str, np.ndarray], node: str) -> float:
        error = observed[node] - prediction[node]
        return float(np.mean(error[np.isfinite(error)] ** 2)) if np.isfinite(error).any() else 0.0

    best = max(observed, key=lambda k: (mean_square(null, k) - mean_square(after, k)) / scales[k] ** 2)
    change = after[best] - null[best]
    residual = observed[best] - null[best]
    mask = np.isfinite(residual) & np.isfinite(change)
    r, c = residual[mask], change[mask]
    norm = float(np.sqrt(np.sum(r**2) * np.sum(c**2)))
    cosine = float(np.sum(r * c)) / norm if norm > 0 else 0.0
    removed = 1.0 - mean_square(after, best) / max(mean_square(null, best), 1e-300)
    overall = evidence.test_improvement
    against_base = (f"against the base model it removes {100 * overall:.0f} % of the test error over all sensors"
                    if overall >= 0 else
                    f"against the base model the test error over all sensors grows {100 * -overall:.0f} %")
    if np.any(c):
        follows = (f"residual on {local_name(best)} follows what {what} adds (cosine {cosine:.2f}); it removes "
                   f"{100 * removed:.0f} % of that sensor's test error (the refit's other parameters kept)")
    else:
        follows = f"{what}, as fitted, adds nothing at any sensor (it sits at its null)"
        against_base += " (the refit's other parameters moved it, not the effect)"
    evidence.explanation = (f"{lead}; " if lead else "") + f"{follows}; {against_base}; {fit_text}"


def _evaluate_together(jobs: Sequence[CandidateJob], shared: AssembledModel,
                       tell: Callable[[tuple[str, str]], None]) -> list[EffectEvidence]:
    """The candidates ``jobs`` evaluated side by side, one thread each, their simulations made by
    ``shared`` (the base with all their effects, :mod:`service.diagnosis.shared_runs`); ``tell``
    gets (effect, node) as each is done."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    first = jobs[0]
    runs = SharedRuns(ModelData(shared, first.data, first.substeps, first.compared), len(jobs))

    def one(index: int) -> EffectEvidence:
        try:
            evidence = _evaluate_candidate(jobs[index], runs.seat(index))
        finally:
            runs.leave()
        tell((evidence.effect, evidence.node))
        return evidence

    with ThreadPoolExecutor(max_workers=len(jobs)) as pool:
        return list(pool.map(one, range(len(jobs))))


def rank_catalog(store: GraphStore, model_name: str, library: dict[str, Signature], base, *, seed: int,
                 refit_max_nfev: int, workers: int | None, say, drifting: Sequence[str] = (),
                 failing_noise: Mapping[str, float] | None = None) -> tuple[list[EffectEvidence], list[str]]:
    """Every applicable (effect, node) candidate, and a drift of the parameters of the components
    ``drifting`` (IRIs) that the failing sensors ``failing_noise`` (node → σ) would show
    (:mod:`service.diagnosis.drift`), evaluated against ``base`` (a
    :class:`~service.calibration.run.CalibrationOutcome` with a test window) and ranked, in
    ``workers`` processes (default: one per candidate, at most the usable CPUs); returns (ranked
    evidence, the reasons the others do not apply)."""
    md, model = base.model_data, base.model
    substeps, data = md.substeps, md.data
    train_slice, test_slice = base.train, base.test
    say("testing the effect catalog")
    candidates, skipped = effect_candidates(store, model_name, library)
    readable = []  # an effect may read a device the base leaves out (a room sensor): its column joins the data
    for candidate in candidates:
        extended, lacking = with_series_of(data, candidate.model)
        if lacking:
            skipped.append(f"{candidate.signature.id} at {local_name(candidate.node)}: it reads the column "
                           f"{', '.join(lacking)}, which the data file lacks")
        else:
            data = extended
            readable.append(candidate)
    candidates = readable
    fit_windows, run_window, evaluation = split_windows(train_slice, test_slice)
    scales = dict(md.problem(train_slice).target_scales)
    say("refitting the base model on the comparison's fit windows")
    refit = refit_calibrator(seed, refit_max_nfev).fit(md.problem(fit_windows, default=base.theta, target_scales=scales))
    fractions = sample_fractions(refit.residuals_)
    base_theta = {ref.key: float(v) for ref, v in zip(model.estimated_parameters, refit.theta_)}
    # judged against the better base prediction of the evaluation half: refitted on the fit windows,
    # or as trained (a fault in the test window's first half can bend the refit)
    observed = md.observed(evaluation)
    base_evaluation = min(_predict_evaluation(md, run_window, evaluation, refit.theta_, base.theta),
                          key=lambda prediction: weighted_test_error(observed, prediction, scales))
    train_theta = {ref.key: float(v) for ref, v in zip(model.estimated_parameters, base.theta)}
    unidentified = frozenset(e.key for e in base.record.estimates if not e.identified)
    drifts = drift_candidates(md, base.theta, drifting, test=test_slice, fit_windows=fit_windows,
                              noise=failing_noise or {}) if drifting else []
    jobs = [
        CandidateJob(
            signature=signature, node=node, model=candidate_model, drift_onsets=onsets, data=data, substeps=substeps,
            fit_windows=fit_windows, run_window=run_window, evaluation=evaluation, base_theta=base_theta,
            base_mean_squares=mean_squares(refit.residuals_, scales), sample_fractions=fractions, target_scales=scales,
            base_evaluation_prediction=base_evaluation, seed=seed, refit_max_nfev=refit_max_nfev,
            train_theta=train_theta, train_unidentified=unidentified,
            onset_windows=([train_slice], slice(test_slice.start, evaluation.start)), compared=md.compared,
        )
        for signature, node, candidate_model, onsets in [(c.signature, c.node, c.model, ()) for c in candidates]
        + [(None, d.node, d.model, d.onsets) for d in drifts]
    ]
    if not jobs:
        return [], skipped
    workers = max(1, min(len(jobs), workers if workers is not None else usable_cpu_count()))
    groups = [list(range(start, len(jobs), workers)) for start in range(workers)]
    shared = [shared_model(store, model_name, library, [EffectRequest(jobs[i].signature.id, jobs[i].node)
                                                        for i in group if jobs[i].signature is not None])
              for group in groups]
    tasks = [([jobs[i] for i in group], model) for group, model in zip(groups, shared)]
    done, counting = [], threading.Lock()

    def told(item: tuple[str, str]) -> None:  # saying how far the catalog is as each candidate is done
        with counting:
            done.append(item)
            say(f"effect {len(done)} of {len(jobs)} refitted: {item[0]} at {local_name(item[1])}")

    if workers > 1:  # the workers tell through a queue the main thread reads
        # forked from a fork server, not from this process: a fork copies its threads' locks (the candidates'
        # thread pools, a service's) and once aborted a worker in the suite; the server imports this module once
        context = get_context("forkserver")
        context.set_forkserver_preload([__name__])
        with context.Manager() as manager, ProcessPoolExecutor(max_workers=workers, mp_context=context,
                                                               initializer=exit_with_parent) as pool:
            queue = manager.Queue()
            futures = [pool.submit(_evaluate_together, group_jobs, model, queue.put) for group_jobs, model in tasks]
            while len(done) < len(jobs) and not any(f.done() and f.exception() for f in futures):
                try:
                    told(queue.get(timeout=0.2))
                except Empty:
                    pass
            results = [future.result() for future in futures]
    else:
        results = [_evaluate_together(group_jobs, model, told) for group_jobs, model in tasks]
    evidence: list[EffectEvidence] = [None] * len(jobs)
    for group, items in zip(groups, results):
        for i, item in zip(group, items):
            evidence[i] = item
    for job, item in zip(jobs, evidence):
        item.model = item.model or job.model
    return rank_evidence(evidence), skipped
