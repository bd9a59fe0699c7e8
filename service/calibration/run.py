"""A calibration run end to end: assemble, read the data, fit, evaluate, write every result as triples.

:func:`calibrate` is what ``graphtwin calibrate`` and the HTTP job run: point (multi-start least
squares; the 16–84 % interval θ̂ ± one standard error, clipped to the prior) or Bayesian
(Kennedy–O'Hagan, PT-MCMC to 20 IATs, posterior predictive intervals on the test window). The test
window is simulated as the continuation of the training run; with one, the error per operating
regime is recorded. ``start_from`` starts from another model's latest calibration
(:func:`calibrated_start`). A run is written in ONE transaction after the fit: a reader sees all of
it or none; a failed run writes nothing. More: ``docs/calibration.md``, *The calibration run*.
"""

from __future__ import annotations

import hashlib
import os
import re
import uuid
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyoxigraph as ox

from service.calibration.metrics import target_metrics
from service.calibration.model_data import DEFAULT_GP_INPUTS, ModelData
from service.calibration.point import NonFiniteSimulationError, PointCalibrator
from service.calibration.record import (
    PREDICTIVE_BAND_LEVEL,
    CalibrationDiagnostics,
    CalibrationRecord,
    PredictiveBand,
    SamplerConvergence,
    discrepancy_table,
    parameter_estimates,
)
from service.calibration.regime_breakdown import RegimeBreakdown, regime_breakdown
from service.calibration.triples import calibration_triples
from service.calibration.unit_mixup import inputs_off_scale, temperature_inputs_misread, unit_mixups
from service.calibration.versus_start import worse_than_start
from service.data.measurements import MeasuredData
from service.data.model_series import SETTLING_S, read_model_data
from service.data.operating_filter import operating_mask
from service.data.windows import Window
from service.errors import CalibrationError
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.graph.units import convert, unit_label
from service.model.assembled_model import AssembledModel
from service.model.assembly import assemble
from service.model.assembly_triples import assembly_iri, assembly_triples
from service.model.simulator import loop_substeps
from service.model.wiring import parameter_label, without_model

if TYPE_CHECKING:  # the Bayesian calibrator (emcee) loads with a Bayesian run
    from service.calibration.bayesian import BayesianCalibrator

__all__ = ["CalibrationOutcome", "calibrate", "calibrated_start", "model_version",
           "fit_point", "continuation", "predict_test", "store_run"]


def model_version(store: GraphStore, model_name: str) -> str:
    """First 12 hex digits of the SHA-256 of the model graph's sorted N-Triples."""
    data = store.backend.dump(store.model_graph(model_name), ox.RdfFormat.N_TRIPLES)
    lines = sorted(line for line in data.decode("utf-8").splitlines() if line.strip())
    return hashlib.sha256("\n".join(lines).encode("utf-8")).hexdigest()[:12]


#: A test-window input counts as beyond the training's when it leaves the training's range by more
#: than this share of that range.
BEYOND_TRAINING_SHARE = 0.05


def inputs_beyond_training(md: ModelData, train: slice, test: slice) -> list[str]:
    """One sentence per boundary input the test window drives beyond the range the training window
    saw (by more than :data:`BEYOND_TRAINING_SHARE` of that range): there the prediction rests on
    what the training could not show (a valve's dead band fitted just above the highest command the
    training day reached, a coil's capacity never exercised), so a test error there says little
    about the model and a fault-free day can look failed."""
    notes = []
    for component in md.model.boundary_inputs:
        node = md.node_of[component]
        seen, tested = md.data.series[node][train], md.data.series[node][test]
        seen, tested = seen[np.isfinite(seen)], tested[np.isfinite(tested)]
        if not seen.size or not tested.size:
            continue
        low, high = float(seen.min()), float(seen.max())
        margin = BEYOND_TRAINING_SHARE * max(high - low, 1e-9)
        above, below = tested > high + margin, tested < low - margin
        if above.any() or below.any():
            column_unit = md.data.source_units.get(node, md.data.units[node])  # said as the column reads
            extreme, reached = convert([tested.max(), high] if above.any() else [tested.min(), low],
                                       md.data.units[node], column_unit)
            unit = unit_label(column_unit)
            reach = (f"{'up' if above.any() else 'down'} to {f'{extreme:.3g} {unit}'.rstrip()} where training "
                     f"reached {reached:.3g}")
            notes.append(f"the test window drives {local_name(node)} beyond what the training window saw "
                         f"({int(above.sum() + below.sum())} steps, {reach}): predictions there rest on what "
                         "the training could not show")
    return notes


def continuation(train: slice, test: slice) -> slice | None:
    """The window from the training start to the test end when the test follows the training."""
    return slice(train.start, test.stop) if test.start >= train.start else None


def predict_test(md: ModelData, train: slice, test: slice, theta: np.ndarray,
                 settling_s: float | None = None) -> dict[str, np.ndarray]:
    """Target node → prediction on ``test`` for one θ: the continuation of the training run when the
    test follows the training start, else a run of its own (warmed up over the data before it) whose
    first ``settling_s`` are NaN (the warm-up settles the model's states, it cannot give them the
    building's; None: :meth:`ModelData.unscored_start_s`)."""
    joined = continuation(train, test)
    if joined is not None:
        offset = test.start - joined.start
        return {k: v[0][offset:] for k, v in md.simulate_targets(joined, theta[None, :]).items()}
    settling = md.unscored_start_steps(test, settling_s)
    out = {}
    for node, values in md.simulate_targets(test, theta[None, :]).items():
        values = values[0].copy()
        values[:settling] = np.nan
        out[node] = values
    return out


def fit_point(md: ModelData, train: slice, *, seed: int, default: np.ndarray | None = None,
              n_starts: int = 2, n_candidates: int = 32, max_nfev: int = 40) -> tuple[PointCalibrator, object]:
    """Point calibration on ``train``; returns the fitted calibrator and the problem."""
    problem = md.problem(train, default=default)
    calibrator = PointCalibrator(n_starts=n_starts, n_candidates=n_candidates, random_state=seed, max_nfev=max_nfev)
    with _non_finite_named(md, train, problem.default):
        return calibrator.fit(problem), problem


@contextmanager
def _non_finite_named(md: ModelData, window: slice, theta: np.ndarray):
    """Add to a :class:`NonFiniteSimulationError` the component output where the simulation of
    ``window`` at ``theta`` first gives NaN or an infinite value."""
    try:
        yield
    except NonFiniteSimulationError as exc:
        source = md.non_finite_source(window, theta)
        raise NonFiniteSimulationError(f"{exc}; it starts at {source}" if source else str(exc)) from None


@dataclass
class CalibrationOutcome:
    """A finished run: the record (as written to the store) and what reports need beside it."""

    record: CalibrationRecord
    model: AssembledModel
    model_data: ModelData
    theta: np.ndarray
    train: slice
    test: slice | None
    predictions: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # window → node → median
    intervals: dict[str, dict[str, dict[float, tuple[np.ndarray, np.ndarray]]]] = field(default_factory=dict)
    calibrator: PointCalibrator | BayesianCalibrator | None = None  # the fitted calibrator (chains for plots)
    regimes: RegimeBreakdown | None = None  # the test-window error per operating regime


def calibrated_start(store: GraphStore, start_from: str, model_name: str,
                     model: AssembledModel) -> tuple[np.ndarray, list[str], str]:
    """θ to start ``model``'s calibration from, the IRIs of the runs its values come from, and a
    sentence saying what it holds. For each estimated parameter: the latest calibrated value (the MAP,
    ``calibrated-parameters.rq``) of the same parameter of the same component in model ``start_from``
    (keys matched without the model name, :func:`without_model`), clipped to this model's bounds; the
    component default where ``start_from`` has none (the parameters of an effect just added).

    :raises CalibrationError: ``start_from`` is not in the store, has no calibration run, or shares no
        estimated parameter with ``model``.
    """
    if not store.has_model(start_from):
        raise CalibrationError(f"start from {start_from!r}: no such model in the store; it holds "
                               f"{', '.join(store.models()) or 'none'}")
    latest = {without_model(f"{row['component'].value}#{row['name'].value}"):
              (float((row.get("map") or row["median"]).value), row["run"].value)
              for row in store.run_named_query("calibrated-parameters", model=start_from)}
    if not latest:
        raise CalibrationError(f"start from {start_from!r}: the model has no calibration run in the store; "
                               "calibrate it first")
    theta = np.array([ref.spec.default for ref in model.estimated_parameters])
    at_default, runs = [], set()
    for j, ref in enumerate(model.estimated_parameters):
        key = without_model(ref.key)
        if key in latest:
            value, run = latest[key]
            theta[j] = min(max(value, ref.spec.lower), ref.spec.upper)
            runs.add(run)
        else:
            at_default.append(parameter_label(ref.key))
    if not runs:
        raise CalibrationError(f"start from {start_from!r}: its calibrated parameters ({', '.join(sorted(latest))}) include "
                               f"none that model {model_name} estimates")
    made = []
    for run in sorted(runs):
        sources = [row["source"].value for row in store.run_named_query("run-data-sources", run=ox.NamedNode(run))]
        made.append(local_name(run) + (f" on {', '.join(sources)}" if sources else ""))
    note = (f"started from the latest calibration of {start_from} ({'; '.join(made)}): {len(theta) - len(at_default)} "
            f"of {len(theta)} parameters" + (f"; at their defaults: {', '.join(at_default)}" if at_default else ""))
    return theta, sorted(runs), note


@dataclass(frozen=True, kw_only=True)
class PreparedCalibration:
    """A calibration checked and ready to fit: the model (its version first), bound to its data, the
    windows as slices, what the run notes about them, the GP inputs, and the start."""

    version: str
    model: AssembledModel
    model_data: ModelData
    train: slice
    test: slice | None
    unscored_s: float
    gp_nodes: tuple[str, ...]
    window_notes: list[str]
    start: np.ndarray | None = None
    start_runs: list[str] | None = None
    start_note: str | None = None


#: A window's end written as a date alone (``2026-01-14``): read as that day's midnight.
_DATE_ONLY = re.compile(r"\d{4}-\d{2}-\d{2}")


def _operating_filter_notes(md: ModelData, only_when: Sequence[str], train: slice, test: slice | None) -> list[str]:
    """What ``--only-when`` keeps of each window, as notes.

    :raises CalibrationError: it keeps no step of a window (named with the conditions)."""
    if md.compared is None or not only_when:
        return []
    conditions = " and ".join(only_when)
    notes = []
    for name, window in (("training", train), ("test", test)):
        if window is None:
            continue
        kept, steps = int(md.compared[window].sum()), window.stop - window.start
        if kept == 0:
            raise CalibrationError(f"--only-when {conditions} holds at none of the {steps} steps of the {name} window: "
                                   "nothing is left to compare there; choose conditions the window meets, or another "
                                   "window")
        notes.append(f"compared only where {conditions}: {kept} of the {name} window's {steps} steps")
    return notes


def _ends_on_a_day_the_data_go_into(data: MeasuredData, end: str | None, window: slice | None) -> bool:
    """Whether a window's ``end`` is a date alone (``2026-01-14``), read as that day's midnight,
    while the data go on into that day: then the window holds one step of it, which is seldom meant
    (data that stop before that midnight make the date a fine end)."""
    if window is None or not isinstance(end, str) or not _DATE_ONLY.fullmatch(end.strip()):
        return False
    return window.stop < data.n_steps and data.timestamps[window.stop - 1] == np.datetime64(end.strip(), "s")


def prepare_calibration(
    store: GraphStore, model_name: str, data_path: Path | str, *, train: Window = (None, None),
    test: Window | None = None, method: str = "point", substeps: int | None = None, only_when: Sequence[str] = (),
    min_test_steps: int = 1, gp_inputs: Sequence[str] | None = None, start_from: str | None = None,
    data_name: str | None = None,
) -> PreparedCalibration:
    """Everything :func:`calibrate` checks before it fits (parameters as there; ``data_name``: what
    messages call the data file): what a job checks at submission.

    :raises CalibrationError, InputError, MeasurementError, AssemblyError: as :func:`calibrate`.
    """
    if method not in ("point", "bayes"):
        raise CalibrationError(f"unknown method {method!r}: use point or bayes")
    version = model_version(store, model_name)  # of the model calibrated, read before anything else
    model = assemble(store, model_name)
    data = read_model_data(model, data_path, source_name=data_name)
    substeps = substeps or loop_substeps(model, data.step_s)
    md = ModelData(model, data, substeps, operating_mask(data, only_when))
    train_slice = data.window(*train, label="training window")
    test_slice = data.window(*test, label="test window") if test is not None else None
    window_notes = [f"the {name} window ends at {end.strip()}T00:00, the first instant of that day (a date alone is "
                    f"its midnight): write {end.strip()}T23:59 to include the day"
                    for name, end, cut in (("training", train[1], train_slice),
                                           ("test", test[1] if test else None, test_slice))
                    if _ends_on_a_day_the_data_go_into(data, end, cut)]
    if test_slice is not None:
        if test_slice.stop - test_slice.start < min_test_steps:
            raise CalibrationError(f"the test window {test[0] or ''}/{test[1] or ''} holds {test_slice.stop - test_slice.start} "
                                   f"steps of data: at least {min_test_steps} are needed")
        overlap = min(train_slice.stop, test_slice.stop) - max(train_slice.start, test_slice.start)
        if overlap > 0:
            steps = "step" if overlap == 1 else "steps"
            window_notes.append(f"the test window overlaps the training window by {overlap} {steps} (a window's end is "
                                "inclusive): its metrics are partly on data the calibration fitted")
        window_notes += inputs_beyond_training(md, train_slice, test_slice)
    window_notes += _operating_filter_notes(md, only_when, train_slice, test_slice)
    unmeasured = [n for n, v in md.observed(test_slice).items() if not np.isfinite(v).any()] if test_slice else []
    if unmeasured:  # said before the fit (the training window's: by its problem), not as a metric's failure after it
        raise CalibrationError("; ".join(
            f"target {local_name(n)} (column {data.columns.get(n, '?')!r}) has no measurements in the test window "
            f"{data.shown(data.timestamps[test_slice.start])} – {data.shown(data.timestamps[test_slice.stop - 1])} "
            "(a gap covers it, or the operating conditions leave none): choose a window where the column has values"
            for n in unmeasured))
    unscored_s = md.unscored_start_s(train_slice)
    train_s = (train_slice.stop - train_slice.start) * data.step_s
    if train_s <= unscored_s:
        raise CalibrationError(f"the training window {train[0] or ''}/{train[1] or ''} holds {train_s / 3600:.3g} h of data, and "
                               f"its first {unscored_s / 3600:g} h are simulated, not scored (the model's start state "
                               f"settles): give a window longer than {unscored_s / 3600:g} h, or one starting later in the data")
    if unscored_s > SETTLING_S:
        window_notes.append(f"the training window's first {unscored_s / 3600:g} h are simulated, not scored: before the "
                            "data's first step the model's start state is a guess, and its slowest loop carries it that "
                            "long; data from before the window would let the fit use them")
    if method == "point" and gp_inputs is not None:
        raise CalibrationError("GP inputs choose the discrepancy's inputs of a Bayesian calibration (--method bayes); "
                               "a point calibration has no discrepancy")
    gp_nodes = md.gp_input_nodes(DEFAULT_GP_INPUTS if gp_inputs is None else gp_inputs)
    start = start_runs = start_note = None
    if start_from is not None:
        start, start_runs, start_note = calibrated_start(store, start_from, model_name, model)
    return PreparedCalibration(
        version=version, model=model, model_data=md, train=train_slice, test=test_slice, unscored_s=unscored_s,
        gp_nodes=tuple(gp_nodes), window_notes=window_notes, start=start, start_runs=start_runs, start_note=start_note)


def calibrate(
    store: GraphStore,
    model_name: str,
    data_path: Path | str,
    *,
    train: Window = (None, None),
    test: Window | None = None,
    method: str = "point",
    seed: int = 0,
    substeps: int | None = None,
    bayes_settings: dict | None = None,
    progress: bool = False,
    on_progress: Callable[[str], None] | None = None,
    only_when: Sequence[str] = (),
    min_test_steps: int = 1,
    gp_inputs: Sequence[str] | None = None,
    start_from: str | None = None,
    on_prepared: Callable[[], None] | None = None,
) -> CalibrationOutcome:
    """Calibrate ``model_name`` against the CSV at ``data_path`` and store the run. A test window
    that overlaps the training window is noted in the run's warnings (its metrics are then partly on
    data the fit saw).

    :param only_when: operating conditions (``"SF Spd Cmd (%) > 5"``, :mod:`service.data.operating_filter`):
        the targets are compared only at the steps where all hold.
    :param min_test_steps: a test window with fewer steps of data is refused.
    :param gp_inputs: the inputs of the discrepancy GP (``method="bayes"`` only; None: the time alone):
        ``"time"`` and boundary inputs by node IRI, local name or CSV column (:meth:`ModelData.gp_input_nodes`).
    :param start_from: a model in the store whose latest calibrated values start this fit
        (:func:`calibrated_start`); None: the component defaults.
    :param on_progress: hears how far a Bayesian run's sampling is after each convergence check.
    :param on_prepared: called once the model, the data and the windows passed their checks, before
        the fit (a caller's "calibrating…" then never precedes a refusal).

    :raises InputError: a bad window, a target without measurements, NaN-only series, an unknown
        method, a ``start_from`` with nothing to start from; nothing is written to the store then.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    started = datetime.now(timezone.utc)
    prepared = prepare_calibration(store, model_name, data_path, train=train, test=test, method=method,
                                   substeps=substeps, only_when=only_when, min_test_steps=min_test_steps,
                                   gp_inputs=gp_inputs, start_from=start_from)
    if on_prepared is not None:
        on_prepared()
    version, model, data, md = prepared.version, prepared.model, prepared.model_data.data, prepared.model_data
    substeps, train_slice, test_slice = md.substeps, prepared.train, prepared.test
    unscored_s, gp_nodes, window_notes = prepared.unscored_s, prepared.gp_nodes, prepared.window_notes
    start, start_runs, start_note = prepared.start, prepared.start_runs, prepared.start_note
    # a point fit screens the components' defaults and runs from the stored start besides; a Bayesian
    # run's walkers start around the problem's default: the stored start
    problem = md.problem(train_slice, gp_inputs=gp_nodes, default=None if method == "point" else start)
    n_par = problem.n_parameters
    settings = {"substeps": substeps, "step_s": data.step_s, "warmup_s": md.warmup_s,
                "unscored_start_s": unscored_s}
    if start_from is not None:
        settings["start_from"] = {"model": start_from, "runs": start_runs}
    if only_when:
        settings["only_when"] = list(only_when)
    if method == "bayes":
        settings["gp_inputs"] = list(gp_nodes)
    diagnostics = CalibrationDiagnostics(
        warnings=list(data.warnings) + list(model.notes) + list(md.simulator.notes) + window_notes,
        start=start_note or None)
    intervals: dict[str, dict[str, dict[float, tuple[np.ndarray, np.ndarray]]]] = {}
    regimes = None
    bands: dict[str, PredictiveBand] = {}
    if method == "point":
        with _non_finite_named(md, train_slice, problem.default if start is None else start):
            calibrator = PointCalibrator(n_starts=2, n_candidates=32, random_state=seed, max_nfev=40).fit(
                problem, kept=None if start is None else start[None, :])
        theta = calibrator.theta_
        se = calibrator.standard_errors_
        lower, upper = problem.lower, problem.upper
        q16, q84 = np.clip(theta - se, lower, upper), np.clip(theta + se, lower, upper)
        theta_map, verdicts = theta, calibrator.identifiability_
        settings.update({"n_starts": 2, "n_candidates": 32, "max_nfev": 40})
        diagnostics.cost = calibrator.cost_
    else:
        from service.calibration.bayesian import BayesianCalibrator

        options = {"n_temperatures": 4, "max_steps": 4000, "check_interval": 100, "progress": progress}
        options.update(bayes_settings or {})
        with _non_finite_named(md, train_slice, problem.default):
            calibrator = BayesianCalibrator(random_state=seed, on_check=on_progress, **options).fit(problem)
        theta = calibrator.median_
        q16, q84, theta_map = calibrator.quantile16_, calibrator.quantile84_, calibrator.map_
        se = calibrator.samples_.std(axis=0)
        verdicts = calibrator.identifiability_
        settings.update({k: v for k, v in options.items() if k != "progress"})
        diagnostics.sampler = SamplerConvergence(
            converged=bool(calibrator.converged_), iat=float(calibrator.iat_),
            n_steps=int(calibrator.n_steps_), acceptance=calibrator.acceptance_)
        if not calibrator.converged_:  # said among the warnings too: they travel with every result
            diagnostics.warnings.append(f"the sampler did not converge in {calibrator.n_steps_} steps (a chain of "
                                        "20 IATs is needed): the estimates, intervals and bands are not to be trusted; "
                                        "run it with more steps (--max-steps, max_steps)")
    predictions = {"train": {k: v[0] for k, v in problem.run(theta[None, :]).items()}}
    metrics = {"train": {
        node: target_metrics(problem.observed[node], predictions["train"][node], n_parameters=n_par,
                             unit=md.units[node], target=node)
        for node in problem.observed
    }}
    if test_slice is not None:
        joined = continuation(train_slice, test_slice)
        offset = test_slice.start - joined.start if joined is not None else 0
        if method == "bayes":
            test_problem = md.problem(joined or test_slice, target_scales=problem.target_scales, settling_s=0.0,
                                      gp_inputs=gp_nodes)
            predictive = calibrator.predict(test_problem, n_draws=200,
                                            steps_from_training_start=(joined or test_slice).start - train_slice.start)
            median = {k: v[offset:] for k, v in predictive.median.items()}
            intervals["test"] = {node: {level: tuple(b[offset:] for b in predictive.interval(node, level))
                                        for level in (0.5, 0.68, 0.9, 0.95, 0.99)} for node in median}
            bands = {node: PredictiveBand("test", PREDICTIVE_BAND_LEVEL, *levels[PREDICTIVE_BAND_LEVEL])
                     for node, levels in intervals["test"].items()}
        else:
            median = predict_test(md, train_slice, test_slice, theta)
        predictions["test"] = median
        observed_test = {node: np.where(np.isfinite(median[node]), values, np.nan)
                         for node, values in md.observed(test_slice).items()}
        metrics["test"] = {
            node: target_metrics(observed_test[node], median[node], n_parameters=n_par,
                                 intervals=intervals.get("test", {}).get(node), unit=md.units[node], target=node)
            for node in observed_test
        }
        regimes = regime_breakdown(md, test_slice, observed_test, median, seed=seed)
    # a column in another unit than the graph declares (°F under °C): the last window against the fit
    # and against the defaults, which a fit bent towards the misread column has not moved
    if test_slice is not None:
        at_defaults = predict_test(md, train_slice, test_slice, md.default_theta())
        compared = observed_test, [predictions["test"], at_defaults]
    else:
        at_defaults = {k: v[0] for k, v in problem.run(md.default_theta()[None, :]).items()}
        compared = problem.observed, [predictions["train"], at_defaults]
    diagnostics.warnings += unit_mixups(data, md.units, *compared)
    diagnostics.warnings += inputs_off_scale(data, model, md.node_of)  # an input the model cannot predict
    diagnostics.warnings += temperature_inputs_misread(md, test_slice or train_slice, problem.target_scales)
    finished = datetime.now(timezone.utc)
    times = data.timestamps
    as_datetime = lambda s: times[s].astype("datetime64[s]").astype(datetime).replace(  # noqa: E731
        tzinfo=timezone.utc if data.utc else None)  # the data's clock: UTC, or local (no offset) as the file gives it
    record = CalibrationRecord(
        run_id=f"{model_name}-{method}-{uuid.uuid4().hex[:8]}", model_name=model_name,
        model_version=version, method=method, seed=seed,
        data_source=Path(data_path).name,
        train_window=(as_datetime(train_slice.start), as_datetime(train_slice.stop - 1)),
        test_window=(as_datetime(test_slice.start), as_datetime(test_slice.stop - 1)) if test_slice else None,
        started=started, finished=finished, settings=settings,
        estimates=parameter_estimates(model, theta, q16, q84, theta_map, se, verdicts), metrics=metrics,
        diagnostics=diagnostics,
        regimes=regimes.rows() if regimes is not None else [],
        regime_rule_accuracy=regimes.rule_accuracy if regimes is not None else float("nan"),
        predictive_bands=bands,
        discrepancy=discrepancy_table(calibrator.discrepancy_, md, gp_nodes) if method == "bayes" else {},
    )
    if start_runs:  # a sensor the model it started from fitted better on these data
        diagnostics.warnings += worse_than_start(store, start_runs, record, model, start, theta)
    store_run(store, model, model_name, record)
    return CalibrationOutcome(record, model, md, theta, train_slice, test_slice, predictions, intervals,
                              calibrator, regimes)


def store_run(store: GraphStore, model: AssembledModel, model_name: str, record: CalibrationRecord,
              extra: list[ox.Triple] | None = None) -> None:
    """Write the assembly (its own graph) and the run (one graph, one transaction)."""
    store.write_graph(store.assembly_graph(model_name), assembly_triples(model, model_name))
    triples = calibration_triples(record, model_graph=store.model_graph(model_name).value,
                                  assembly=assembly_iri(model_name).value)
    store.write_graph(store.run_graph(record.run_id), triples + list(extra or []))


