"""How the commands print results: tables of metrics, estimates, regimes and diagnoses, notes, plots."""

from __future__ import annotations

import math
import re
import shlex
from pathlib import Path
from typing import TYPE_CHECKING

from rich.table import Table
from rich.text import Text

from service.calibration.metrics import on_interval_scale
from service.cli.common import DEFAULT_STORE, console
from service.graph.namespaces import local_name
from service.graph.units import (
    difference_label,
    difference_text,
    difference_unit,
    logged_scale_text,
    quantity_text,
    unit_label,
)
from service.model.wiring import parameter_label

if TYPE_CHECKING:  # the calibration and diagnosis modules load with the commands that run them
    from service.calibration.record import CalibrationRecord
    from service.diagnosis.report import DiagnosisReport

__all__ = ["print_metrics", "print_calibration", "print_regimes", "print_data_warnings", "print_diagnosis",
           "save_diagnosis_plots"]

#: A parameter key (``<component IRI>#<name>``) in a sentence, read as ``<node>.<name>`` (:func:`parameter_label`).
_PARAMETER_KEY = re.compile(r"\S*/component/[^\s#]+#\w+")


def print_metrics(title: str, metrics: dict, logged_units: dict[str, str] | None = None) -> None:
    """Per sensor: RMSE, the measurement noise σ its residual shows and RMSE/σ (about 1 for a model
    right to the noise), MAE, R², CV(RMSE), NMBE (– for a temperature in °C or °F, whose mean
    depends on the scale's zero, and for a mean within the noise of zero) and, for a Bayesian run's prediction intervals, the ACE and mean
    width of the 90 % one (every level: ``--json``). ``logged_units``: the unit each sensor's column
    was logged in; where it is not the errors' (°F for K), the caption says what one of theirs is."""
    intervals = any(m.coverage for m in metrics.values())
    table = Table(title=title)
    for column in ("sensor", "RMSE", "noise σ", "RMSE / σ", "MAE", "R²", "CV(RMSE) %", "NMBE %",
                   *(("ACE 90 % (points)", "90 % width") if intervals else ()), "unit"):
        table.add_column(column, overflow="fold")
    for node, m in metrics.items():
        interval_cells = []
        if intervals:
            at_90 = min(m.coverage, key=lambda c: abs(c.level - 0.9), default=None)
            interval_cells = [f"{100 * at_90.ace:+.1f}", f"{at_90.mean_width:.3g}"] if at_90 else ["–", "–"]
        ratios = (["–", "–"] if on_interval_scale(m.unit) or not math.isfinite(m.cv_rmse_percent)
                  else [f"{m.cv_rmse_percent:.1f}", f"{m.nmbe_percent:+.1f}"])
        table.add_row(local_name(node), f"{m.rmse:.3g}", f"{m.noise:.3g}", f"{m.rmse / m.noise:.1f}" if m.noise > 0 else "–",
                      f"{m.mae:.3g}", f"{m.r2:.3f}", *ratios, *interval_cells, difference_label(m.unit))
    restated = sorted({scale for node, m in metrics.items()
                       if (scale := logged_scale_text(m.unit, (logged_units or {}).get(node, "")))})
    if restated:  # the data's own degrees
        table.caption = "as logged: " + "; ".join(restated)
    console.print(table)


def _first_reason(reasons) -> str:
    """An unidentified parameter's verdict for the table: its first reason, and how many more the JSON
    and the report page list (the whole list ran to ten lines a parameter on the school AHU)."""
    more = f" (+{len(reasons) - 1} more in --json)" if len(reasons) > 1 else ""
    return "no: " + _PARAMETER_KEY.sub(lambda m: parameter_label(m[0]), reasons[0] if reasons else "") + more


def print_calibration(record: CalibrationRecord, logged_units: dict[str, str] | None = None) -> None:
    """A calibration run as tables: the estimates, the start and the sampler's convergence, the
    metrics per window (``logged_units``: :func:`print_metrics`), the regimes, the notes."""
    table = Table(title=f"Estimates ({record.method}, run {record.run_id})")
    for column in ("component", "parameter", "estimate", "16–84 %", "unit", "identified"):
        table.add_column(column, overflow="fold")
    for e in record.estimates:
        table.add_row(local_name(e.node), e.name, f"{e.median:.4g}", f"{e.quantile16:.4g} – {e.quantile84:.4g}", unit_label(e.unit),
                      "yes" if e.identified else _first_reason(e.reasons))
    identified = sum(e.identified for e in record.estimates)
    table.caption = f"{identified} of {len(record.estimates)} estimated parameters identified by these data"
    console.print(table)
    if 2 * identified < len(record.estimates):
        console.print(f"Only {identified} of {len(record.estimates)} estimated parameters are identified: the "
                      "others fit the training window about as well anywhere over much of their ranges, so "
                      "predictions for operation it did not show are uncertain; data with more varied operation, or a "
                      "measurement of what they set, would pin them (docs/calibration.md, \"Identifiability verdicts\").",
                      markup=False, highlight=False)
    if record.diagnostics.start is not None:
        console.print(record.diagnostics.start, markup=False, highlight=False)
    if record.diagnostics.sampler is not None:
        console.print(f"PT-MCMC: {record.diagnostics.sampler.describe()}", markup=False, highlight=False)
    if record.discrepancy:
        print_discrepancy(record)
    bounds = {"train": record.train_window, "test": record.test_window}
    for window, metrics in record.metrics.items():
        span = bounds.get(window)
        print_metrics(f"Metrics, {window} window" + (f" ({span[0]:%Y-%m-%d %H:%M} – {span[1]:%Y-%m-%d %H:%M})"
                                                     if span else ""), metrics, logged_units)
    print_regimes(record)
    print_data_warnings(record.diagnostics.warnings)


def print_discrepancy(record: CalibrationRecord) -> None:
    """A Bayesian run's discrepancy GP per target: amplitude σ_f, noise σ_n and length scales, each its
    posterior median with the 16–84 % interval: how much of the misfit the discrepancy took."""
    names = list(dict.fromkeys(name for entries in record.discrepancy.values() for name in entries))
    table = Table(title="Discrepancy GP per sensor (posterior median, 16–84 %)")
    table.add_column("sensor", overflow="fold")
    for name in names:
        table.add_column(name.replace("length_scale:", "length scale, "), overflow="fold")

    def cell(value: tuple[float, float, float, str] | None) -> str:
        if value is None:
            return "–"
        median, q16, q84, unit = value
        return f"{quantity_text(median, unit)} ({q16:.3g}–{q84:.3g})"

    for target, entries in record.discrepancy.items():
        table.add_row(local_name(target), *(cell(entries.get(name)) for name in names))
    console.print(table)


def print_regimes(record: CalibrationRecord) -> None:
    """The test-window RMSE of each target per operating regime (a run with a test window; a regime
    the test window never enters is left out)."""
    if not record.regimes:
        return
    units = {node: m.unit for node, m in record.metrics.get("test", {}).items()}
    sensors = list(record.regimes[0]["rmse"])
    table = Table(title=f"Test RMSE per operating regime (rule tree accuracy {record.regime_rule_accuracy:.2f})")
    for column in ("regime", "share", *map(local_name, sensors)):
        table.add_column(column, overflow="fold")
    entered = [r for r in record.regimes if r["share"] > 0]
    for row in entered:
        table.add_row(row["rule"], f"{100 * row['share']:.0f} %",
                      *(quantity_text(row["rmse"][n], difference_unit(units.get(n, ""))) for n in sensors))
    if len(entered) < len(record.regimes):
        table.caption = f"{len(record.regimes) - len(entered)} regime(s) the test window never enters left out"
    console.print(table)


def print_data_warnings(warnings: list[str]) -> None:
    """What reading the data, assembling the model and preparing its simulation noticed (frozen
    points, gaps, unused columns; signature choices; a loop broken by a delay), as they are."""
    for warning in warnings:
        console.print(Text(f"note: {warning}", style="yellow"))


def print_diagnosis(report: DiagnosisReport, *, stored: bool = True, data: Path | None = None,
                    store: Path | None = None, model_file: Path | None = None) -> None:
    """The diagnosis as tables and sentences; ``stored``: the run is in a store that outlives this
    command (not ``--memory``), so its report can be made later; ``data``: the measurement file the
    run read (the report command then names it); ``model_file``: the building model, for the command
    that adds the answer to it."""
    from service.diagnosis.drift import (
        drifting_parameter,  # scipy: not at the CLI's start
    )
    from service.diagnosis.localization import describe_locations
    from service.diagnosis.ranking import BIC_THRESHOLD, MIN_TEST_IMPROVEMENT

    print_data_warnings(report.data_warnings)
    table = Table(title="Test window: model vs measurements")
    for column in ("sensor", "RMSE", "RMSE / noise", "NMBE %", "verdict"):
        table.add_column(column, overflow="fold")
    for node, s in report.sensors.items():
        verdict = ("[red]fails[/red]" if s.fails else
                   f"[yellow]within {report.failure_ratio:g}× its noise, but the answer removes ≥ "
                   f"{100 * MIN_TEST_IMPROVEMENT:.0f} % of its error[/yellow]" if s.shows_missing_effect else "matches")
        table.add_row(local_name(node), difference_text(s.rmse, s.unit, s.logged_unit), f"{s.rmse_over_noise:.1f}",
                      "–" if on_interval_scale(s.unit) else f"{s.nmbe_percent:+.1f}", verdict)
    console.print(table)
    for sentence in describe_locations(report.localization):
        console.print(f"• {sentence}")
    worst = next((r for r in report.regimes if r["worst"]), None)
    if worst is not None:
        console.print(f"Worst operating regime ({100 * worst['share']:.0f} % of the test window): {worst['rule']}  "
                      f"[rule tree accuracy {report.regime_rule_accuracy:.2f}]")
    for node, episodes in report.episodes.items():
        for episode in episodes[:3]:
            console.print(f"  {local_name(node)}: {episode.describe()}")
    for node, signals in report.residual_dependence.items():
        for signal in signals:
            console.print(f"  residual of {local_name(node)}: {signal.describe(report.step_s)}")
    if not report.effects_tested:
        console.print(f"[bold]{report.summary}[/bold]")
        return
    table = Table(title="Which effect is missing (best first)",
                  caption=f"significant: ΔBIC < {BIC_THRESHOLD:g} and at least {100 * MIN_TEST_IMPROVEMENT:.0f} % "
                          "of the held-out error removed (negative: the effect, fitted, predicts the held-out data "
                          "worse); score: the score test's χ² at the effect's null, in-sample evidence only")
    for column in ("effect", "at", "score", "ΔBIC", "test error removed", "significant"):
        table.add_column(column, overflow="fold")
    for e in report.effects:
        table.add_row(e.effect, local_name(e.node), f"{e.score.statistic:.1f}", f"{e.delta_bic:.1f}",
                      f"{100 * e.test_improvement:.0f} %",
                      ("yes" if e.significant else "no") + (", ranked below ↓" if e.demoted else ""))
    console.print(table)
    for e in report.effects:
        if e.demoted:
            console.print(f"  ↓ {e.effect} at {local_name(e.node)}: {e.demoted}")
    console.print(f"[bold]{report.summary}[/bold]")
    answer = report.answer
    if answer is not None and model_file is not None and drifting_parameter(answer.effect) is None:
        added = Path(f"{model_file.stem}+{answer.effect}.ttl")
        command = ["graphtwin", "add-effect", str(model_file), "--effect", answer.effect, "--target", answer.node,
                   "-o", str(added)]
        console.print(f"add it to the model: {shlex.join(command)}", markup=False, soft_wrap=True)  # one line to copy
        if answer.appears_in_test_window:
            console.print("  it appeared in the test window: calibrate the model with it on data from after it "
                          "appeared (before, the effect is at its null and its size cannot be fitted)", markup=False)
    if report.told_apart:
        console.print("  not the answer, though significant:", markup=False)
        for other in report.told_apart:
            console.print(f"    – {other.describe()}", markup=False)
    for lookalike in report.indistinguishable:
        console.print(f"  {lookalike.effect.effect} at {local_name(lookalike.effect.node)} would be told apart by:")
        for text in lookalike.would_separate:
            console.print(f"    – {text}")
    for reason in report.not_applicable:
        console.print(f"  not tried: {reason}", style="dim", markup=False)
    if stored:
        named = f" --data {data}" if data is not None and data.resolve().parent != Path.cwd().resolve() else ""
        named += f" --store {store}" if store is not None and store != DEFAULT_STORE else ""
        console.print(f"run {report.run_id}: graphtwin report {report.run_id}-diagnosis{named} -o report.html")
    else:
        console.print(f"run {report.run_id} was in a throw-away store (--memory): run again with --store DIR to keep "
                      "it and make its report (graphtwin report)")


def save_diagnosis_plots(report: DiagnosisReport, folder: Path) -> list[Path]:
    """The test window measured against the base model, and the residuals with the matching band
    and the failure episodes, as PNGs in ``folder``."""
    from service.report.plots import plot_measured_vs_model, plot_residuals

    folder.mkdir(parents=True, exist_ok=True)
    units = {n: s.unit for n, s in report.sensors.items()}
    observed = report.test_observed
    residuals = {n: observed[n] - report.base_test_prediction[n] for n in observed}
    episodes = {n: [(e.start, e.end) for e in found] for n, found in report.episodes.items()}
    thresholds = {n: report.failure_ratio * s.noise for n, s in report.sensors.items()}
    return [
        plot_measured_vs_model(folder / f"{report.run_id}-test.png", report.test_timestamps, observed,
                               {"model": report.base_test_prediction}, units, title="Test window: measured and model"),
        plot_residuals(folder / f"{report.run_id}-residuals.png", report.test_timestamps, residuals, units, thresholds,
                       episodes, title="Test window residuals (shaded: episodes beyond their usual spread; a steady bias has none)"),
    ]
