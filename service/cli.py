"""The ``graphtwin`` command line: the same jobs as the HTTP service, run locally.

Every command that touches the store takes ``--store DIR`` (the embedded Oxigraph store on disk,
default ``./graphtwin-data``) or ``--memory`` (a throw-away in-memory store). A model argument is a
file (Turtle, N-Triples, RDF/XML, JSON-LD), loaded under ``--name`` (default: the file name).
"""

from __future__ import annotations

import csv
import json
import os
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer
from rich.console import Console
from rich.syntax import Syntax
from rich.table import Table
from rich.text import Text

from service.model.assembly import AssemblyError, EffectRequest, assemble
from service.model.summary import assembly_to_dict, print_assembly
from service.model.assembly_triples import assembly_triples
from service.calibration.model_data import DEFAULT_GP_INPUTS
from service.model.effect_recording import applied_effect_triples, record_effect_in_file
from service.data.measurements import MeasurementError
from service.graph.namespaces import local_name
from service.resources import examples_dir
from service.matching.signature import SignatureError
from service.components.library import SignatureLibrary
from service.matching.library_triples import ensure_signature_library
from service.matching.compiler import compile_signature
from service.graph.store import GraphStore, ModelLoadError, StoreInUseError
from service.graph.units import unit_label

if TYPE_CHECKING:  # the calibration and diagnosis modules are imported by the commands that run them
    from service.diagnosis.loop import DiagnosisReport  # (SciPy, scikit-learn: a second of `graphtwin --help`)

__all__ = ["app"]

app = typer.Typer(no_args_is_help=True, add_completion=False, help=__doc__)
signature_app = typer.Typer(no_args_is_help=True, help="Inspect the signature library.")
example_app = typer.Typer(no_args_is_help=True, help="Example models and synthetic data.")
app.add_typer(signature_app, name="signature")
app.add_typer(example_app, name="example")

console = Console()
error_console = Console(stderr=True)

StoreOption = Annotated[Path, typer.Option("--store", help="Embedded store folder (created if missing).")]
MemoryOption = Annotated[bool, typer.Option("--memory", help="Use a throw-away in-memory store.")]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")]
NameOption = Annotated[str | None, typer.Option("--name", help="Model name in the store (default: from the file name).")]
SeedOption = Annotated[int, typer.Option("--seed", help="Random seed (runs are reproducible).")]
OnlyWhenOption = Annotated[list[str] | None, typer.Option(
    "--only-when", help="Compare only at steps where COLUMN OP NUMBER holds, in the column's unit "
                        "(e.g. 'SF Spd Cmd (%) > 5'); repeat for several (all must hold).")]
ModelFileArgument = Annotated[Path, typer.Argument(help="Building model file.")]
MeasurementsArgument = Annotated[Path, typer.Argument(help="Measurement CSV (README: data contract).")]
TrainWindowOption = Annotated[str, typer.Option(help="Training window START/END (ISO; either side may be empty).")]
TestWindowOption = Annotated[str | None, typer.Option(help="Test window START/END.")]
StartFromOption = Annotated[str | None, typer.Option(help=(
    "A model in the store whose latest calibrated parameters start the fit (the version before `add-effect`, "
    "or the model itself: a warm start on new data); the others, an added effect's, start at their defaults."))]
USER_ERRORS = (ModelLoadError, AssemblyError, SignatureError, MeasurementError, FileNotFoundError, ValueError, KeyError)


def open_store(store: Path, memory: bool, *, reading: bool = False) -> GraphStore:
    """The embedded store with the ontology subsets and the signature library loaded; a store another
    process holds, or a signature file with a mistake, is a one-line error (exit code 2). ``reading``:
    the command only reads results, so a folder that holds no store is an error (a mistyped
    ``--store`` would otherwise be a new, empty store)."""
    if reading and not memory and not store.is_dir():
        raise fail(f"no store at {store}: give --store the folder a calibration or diagnosis wrote")
    try:
        graph_store = GraphStore.embedded(None if memory else store)
        graph_store.ensure_ontologies()
        ensure_signature_library(graph_store, SignatureLibrary.load())
    except (*USER_ERRORS, StoreInUseError) as exc:
        raise fail(exc) from None
    return graph_store


def model_name_for(path: Path, name: str | None) -> str:
    """The model's name in the store: ``--name``, else the file stem (the folder named with it for
    ``…/NAME/model.ttl``; ``model`` for a ``model.ttl`` in the current folder)."""
    if name:
        return name
    return path.parent.name if path.stem == "model" and path.parent.name else path.stem


def error_text(exc: BaseException) -> str:
    """What an error says, for a person: a KeyError's message without the quotes ``str`` adds, a
    missing file as ``PATH: No such file or directory``."""
    if isinstance(exc, KeyError) and exc.args:
        return str(exc.args[0])
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror}"
    return str(exc)


def fail(problem: str | BaseException) -> typer.Exit:
    """Print ``problem`` (a message, or an exception as :func:`error_text` reads it) as an error, as
    it is (no markup read in it, no line breaks added) → exit 2."""
    message = problem if isinstance(problem, str) else error_text(problem)
    error_console.print(Text.assemble(("error:", "bold red"), " ", message), soft_wrap=True)
    return typer.Exit(code=2)


def _load(store: GraphStore, model: Path, name: str | None) -> str:
    model_name = model_name_for(model, name)
    if name is None:
        try:
            GraphStore.check_name(model_name)
        except ValueError as exc:
            raise ValueError(f"{exc}; the name comes from {model}: give one with --name") from None
    store.load_model(model_name, model)
    return model_name


@app.command("assemble")
def assemble_command(
    model: ModelFileArgument,
    name: NameOption = None,
    max_complexity: Annotated[int | None, typer.Option(help="Ignore signatures above this complexity.")] = None,
    as_json: JsonOption = False,
    store: StoreOption = Path("graphtwin-data"),
    memory: MemoryOption = False,
) -> None:
    """Load MODEL into the store, assemble its simulation model and write it back as triples."""
    from service.report.brick import brick_report

    graph_store = open_store(store, memory)
    try:
        model_name = _load(graph_store, model, name)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    try:
        assembled = assemble(graph_store, model_name, max_complexity=max_complexity)
    except USER_ERRORS as exc:
        hint = (f"\n{model} is a Brick model: graphtwin brick-report {model} lists what the alignment could not use"
                if brick_report(graph_store, model_name).is_brick else "")
        raise fail(f"{error_text(exc)}{hint}") from None
    graph_store.write_graph(graph_store.assembly_graph(model_name), assembly_triples(assembled, model_name))
    if as_json:
        console.print_json(json.dumps(assembly_to_dict(assembled)))
    else:
        print_assembly(assembled, console)


@app.command("brick-report")
def brick_report_command(
    model: Annotated[Path, typer.Argument(help="Building model file (Brick 1.3/1.4).")],
    name: NameOption = None,
    brick_ontology: Annotated[Path | None, typer.Option(help=(
        "The official Brick ontology file (Brick.ttl): tells an official class graphtwin does not model "
        "from a misspelt one."))] = None,
    as_json: JsonOption = False,
    store: StoreOption = Path("graphtwin-data"),
    memory: MemoryOption = False,
) -> None:
    """What the Brick alignment could not use in MODEL: unaligned classes, unread relations, the
    assumptions it made and the triples that would remove them, points without a column or unit."""
    from service.report.brick import brick_report, official_brick_classes, print_brick_report

    graph_store = open_store(store, memory)
    try:
        official = official_brick_classes(brick_ontology) if brick_ontology is not None else None
        report = brick_report(graph_store, _load(graph_store, model, name), official)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    if as_json:
        console.print_json(json.dumps(report.to_dict()))
    else:
        print_brick_report(report, console)


@signature_app.command("list")
def signature_list() -> None:
    """List the signatures of the library (components and effects)."""
    for signature in SignatureLibrary.load().values():
        console.print(f"{signature.id:24s} {signature.kind:9s} {signature.label}")


@signature_app.command("explain")
def signature_explain(name: Annotated[str, typer.Argument(help="Signature id, e.g. Fan.")]) -> None:
    """Print the SPARQL query a signature compiles to (highlighted on a terminal; the text as it is
    when written to a file or a pipe, so ``explain Fan > fan.rq`` is a query any endpoint runs)."""
    library = SignatureLibrary.load()
    if name not in library:
        raise fail(f"no signature {name!r}; known: {', '.join(sorted(library))}")
    text = compile_signature(library[name]).text
    if console.is_terminal:
        console.print(Syntax(text, "sparql", word_wrap=True))
    else:
        sys.stdout.write(text)


def _print_metrics(title: str, metrics: dict) -> None:
    """Per sensor: RMSE, MAE, R², CV(RMSE), NMBE and, for a Bayesian run's prediction intervals, the
    ACE and mean width of the 90 % one (every level: ``--json``)."""
    intervals = any(m.coverage for m in metrics.values())
    table = Table(title=title)
    for column in ("sensor", "RMSE", "MAE", "R²", "CV(RMSE) %", "NMBE %", *(("ACE 90 %", "90 % width") if intervals else ()),
                   "unit"):
        table.add_column(column)
    for node, m in metrics.items():
        interval_cells = []
        if intervals:
            at_90 = min(m.coverage, key=lambda c: abs(c.level - 0.9), default=None)
            interval_cells = [f"{100 * at_90.ace:+.1f}", f"{at_90.mean_width:.3g}"] if at_90 else ["–", "–"]
        table.add_row(local_name(node), f"{m.rmse:.3g}", f"{m.mae:.3g}", f"{m.r2:.3f}", f"{m.cv_rmse_percent:.1f}",
                      f"{m.nmbe_percent:+.1f}", *interval_cells, unit_label(m.unit))
    console.print(table)


@app.command("calibrate")
def calibrate_command(
    model: ModelFileArgument,
    data: MeasurementsArgument,
    train: TrainWindowOption = "/",
    test: TestWindowOption = None,
    method: Annotated[str, typer.Option(help="point (least squares) or bayes (KOH, PT-MCMC).")] = "point",
    name: NameOption = None,
    seed: SeedOption = 0,
    plots: Annotated[Path | None, typer.Option(help="Folder for measured-vs-model plots.")] = None,
    only_when: OnlyWhenOption = None,
    gp_input: Annotated[list[str] | None, typer.Option(
        help="An input of the discrepancy GP (--method bayes): 'time' (the default) or a boundary input "
             "(node local name, IRI or CSV column); repeat for several.")] = None,
    start_from: StartFromOption = None,
    as_json: JsonOption = False,
    store: StoreOption = Path("graphtwin-data"),
    memory: MemoryOption = False,
) -> None:
    """Calibrate MODEL against DATA; estimates, metrics and provenance are written to the store."""
    from service.calibration.run import calibrate, parse_window

    graph_store = open_store(store, memory)
    try:
        model_name = _load(graph_store, model, name)
        outcome = calibrate(graph_store, model_name, data, train=parse_window(train),
                            test=parse_window(test) if test else None, method=method, seed=seed,
                            progress=not as_json, only_when=only_when or (), gp_inputs=gp_input or DEFAULT_GP_INPUTS,
                            start_from=start_from)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    record = outcome.record
    if plots is not None:
        plots.mkdir(parents=True, exist_ok=True)
        _plot_run(outcome, plots / f"{record.run_id}.png")
    if as_json:
        console.print_json(json.dumps(record.to_dict(), default=str))
        return
    table = Table(title=f"Estimates ({record.method}, run {record.run_id})")
    for column in ("component", "parameter", "estimate", "16–84 %", "unit", "identified"):
        table.add_column(column, overflow="fold")
    for e in record.estimates:
        table.add_row(local_name(e.node), e.name, f"{e.median:.4g}", f"{e.quantile16:.4g} – {e.quantile84:.4g}", e.unit,
                      "yes" if e.identified else "no: " + _PARAMETER_KEY.sub(r"\1.\2", "; ".join(e.reasons)))
    console.print(table)
    if "start" in record.diagnostics:
        console.print(record.diagnostics["start"], markup=False, highlight=False)
    if "converged" in record.diagnostics:
        found = record.diagnostics
        console.print(f"PT-MCMC: {'converged' if found['converged'] else 'NOT converged'} after {found['n_steps']} steps "
                      f"(20 × IAT: IAT {max(found['iat']):.0f} steps; acceptance {float(np.mean(found['acceptance'])):.2f})",
                      markup=False, highlight=False)
    for window, metrics in record.metrics.items():
        _print_metrics(f"Metrics, {window} window", metrics)
    _print_regimes(record)
    _print_data_warnings(record.diagnostics.get("warnings", []))


def _print_regimes(record) -> None:
    """The test-window RMSE of each target per operating regime (a run with a test window)."""
    if not record.regimes:
        return
    units = {node: m.unit for node, m in record.metrics.get("test", {}).items()}
    sensors = list(record.regimes[0]["rmse"])
    table = Table(title=f"Test RMSE per operating regime (rule tree accuracy {record.regime_rule_accuracy:.2f})")
    for column in ("regime", "share", *map(local_name, sensors)):
        table.add_column(column, overflow="fold")
    for row in record.regimes:
        table.add_row(row["rule"], f"{100 * row['share']:.0f} %",
                      *(_with_unit(row["rmse"][n], units.get(n, "")) for n in sensors))
    console.print(table)


def _print_data_warnings(warnings: list[str]) -> None:
    """What reading the data, assembling the model and preparing its simulation noticed (frozen
    points, gaps, unused columns; signature choices; a loop broken by a delay), as they are."""
    for warning in warnings:
        console.print(Text(f"note: {warning}", style="yellow"))


def _plot_run(outcome, path: Path) -> Path:
    from service.report.plots import plot_measured_vs_model

    window = outcome.test if outcome.test is not None else outcome.train
    key = "test" if outcome.test is not None else "train"
    md = outcome.model_data
    intervals = {n: levels[0.9] for n, levels in outcome.intervals.get(key, {}).items()}
    return plot_measured_vs_model(path, md.data.timestamps[window], md.observed(window),
                                  {"model": outcome.predictions[key]}, md.units, intervals or None,
                                  title=f"{outcome.record.model_name}: {key} window")


def _print_diagnosis(report: DiagnosisReport, *, stored: bool = True) -> None:
    """The diagnosis as tables and sentences; ``stored``: the run is in a store that outlives this
    command (not ``--memory``), so its report can be made later."""
    _print_data_warnings(report.data_warnings)
    table = Table(title="Test window: model vs measurements")
    for column in ("sensor", "RMSE", "RMSE / noise", "NMBE %", "verdict"):
        table.add_column(column)
    for node, s in report.sensors.items():
        table.add_row(local_name(node), f"{s['rmse']:.3g} {unit_label(s['unit'])}", f"{s['rmse_over_noise']:.1f}",
                      f"{s['nmbe']:+.1f}", "[red]fails[/red]" if s["fails"] else "matches")
    console.print(table)
    for location in report.localization:
        console.print(f"• {location['text']}")
    worst = next((r for r in report.regimes if r["worst"]), None)
    if worst is not None:
        console.print(f"Worst operating regime ({100 * worst['share']:.0f} % of the test window): {worst['rule']}  "
                      f"[rule tree accuracy {report.regime_rule_accuracy:.2f}]")
    for node, episodes in report.episodes.items():
        for episode in episodes[:3]:
            console.print(f"  {local_name(node)}: {episode['text']}")
    for node, found in report.residual_dependence.items():
        for signal in found["signals"]:
            console.print(f"  residual of {local_name(node)}: {signal['text']}")
    if not report.effects_tested:
        console.print(f"[bold]{report.summary}[/bold]")
        return
    table = Table(title="Which effect is missing (best first)")
    for column in ("effect", "at", "score", "ΔBIC", "test error removed", "significant"):
        table.add_column(column)
    for e in report.effects:
        table.add_row(e.effect, local_name(e.node), f"{e.score.statistic:.1f}", f"{e.delta_bic:.1f}",
                      f"{100 * e.test_improvement:.0f} %", "yes" if e.significant else "no")
    console.print(table)
    console.print(f"[bold]{report.summary}[/bold]")
    if stored:
        console.print(f"run {report.run_id}: graphtwin report {report.run_id}-diagnosis -o report.html")
    else:
        console.print(f"run {report.run_id} was in a throw-away store (--memory): run again with --store DIR to keep "
                      "it and make its report (graphtwin report)")


@app.command("simulate")
def simulate_command(
    model: ModelFileArgument,
    data: Annotated[Path, typer.Argument(help="Measurement CSV (boundary inputs; targets optional for comparison).")],
    params: Annotated[Path | None, typer.Option(help="JSON {parameter name or key: value}; others at their defaults.")] = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="CSV of measured and simulated series.")] = None,
    name: NameOption = None,
    store: StoreOption = Path("graphtwin-data"),
    memory: MemoryOption = False,
) -> None:
    """Simulate MODEL over DATA and write each target's simulation beside its measurement."""
    from service.calibration.model_data import ModelData, read_model_data
    from service.data.measurements import write_comparison_csv
    from service.model.simulator import loop_substeps, target_series

    graph_store = open_store(store, memory)
    try:
        model_name = _load(graph_store, model, name)
        assembled = assemble(graph_store, model_name)
        measured = read_model_data(assembled, data)
        values = json.loads(params.read_text()) if params is not None else {}
        refs = assembled.estimated_parameters
        known = {r.key for r in refs} | {r.name for r in refs}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"{params}: no estimated parameter named {', '.join(unknown)}")
        theta = [float(values.get(r.key, values.get(r.name, r.spec.default))) for r in refs]
        md = ModelData(assembled, measured, loop_substeps(assembled, measured.step_s))
        result = md.simulate_all(slice(0, measured.n_steps), np.array(theta))
    except (*USER_ERRORS, json.JSONDecodeError) as exc:
        raise fail(exc) from None
    simulated = target_series(assembled, result)
    if output is not None:
        write_comparison_csv(output, measured, simulated)
        console.print(f"wrote {output}")
    table = Table(title="Simulated against measured")
    for column in ("sensor", "RMSE", "unit"):
        table.add_column(column)
    for node, values in simulated.items():
        observed = measured.series[node]
        finite = np.isfinite(observed)
        rmse = float(np.sqrt(np.mean((observed[finite] - values[finite]) ** 2))) if finite.any() else float("nan")
        table.add_row(local_name(node), f"{rmse:.3g}", unit_label(measured.units[node]))
    console.print(table)


def _save_diagnosis_plots(report: DiagnosisReport, folder: Path) -> list[Path]:
    """The test window measured against the base model, and the residuals with the matching band
    and the failure episodes, as PNGs in ``folder``."""
    from service.report.plots import plot_measured_vs_model, plot_residuals

    folder.mkdir(parents=True, exist_ok=True)
    units = {n: s["unit"] for n, s in report.sensors.items()}
    observed = report.test_observed
    residuals = {n: observed[n] - report.base_test_prediction[n] for n in observed}
    episodes = {n: [(e["start"], e["end"]) for e in found] for n, found in report.episodes.items()}
    thresholds = {n: report.failure_ratio * s["noise"] for n, s in report.sensors.items()}
    return [
        plot_measured_vs_model(folder / f"{report.run_id}-test.png", report.test_timestamps, observed,
                               {"model": report.base_test_prediction}, units, title="Test window: measured and model"),
        plot_residuals(folder / f"{report.run_id}-residuals.png", report.test_timestamps, residuals, units, thresholds,
                       episodes, title="Test window: where the model fails (shaded: failure episodes)"),
    ]


def _diagnose_cli(model, data, train, test, name, seed, as_json, plots, store, memory, rank_effects,
                  only_when, start_from) -> None:
    from service.calibration.run import parse_window
    from service.diagnosis.loop import diagnose

    graph_store = open_store(store, memory)
    try:
        model_name = _load(graph_store, model, name)
        report = diagnose(graph_store, model_name, data, train=parse_window(train), test=parse_window(test),
                          seed=seed, rank_effects=rank_effects, only_when=only_when or (), start_from=start_from,
                          on_progress=None if as_json else (lambda m: console.print(f"[dim]{m}…[/dim]")))
    except USER_ERRORS as exc:
        raise fail(exc) from None
    if as_json:
        console.print_json(json.dumps(report.to_dict(), default=str))
        return
    _print_diagnosis(report, stored=not memory)
    console.print("plots: " + ", ".join(str(p) for p in _save_diagnosis_plots(report, plots)))


PlotsOption = Annotated[Path, typer.Option(help="Folder for the plots (text output only).")]


def _diagnosis_command(rank_effects: bool, doc: str):
    """The ``diagnose`` (``rank_effects``) or ``compare`` command: the same options, the same report."""

    def command(
        model: ModelFileArgument,
        data: MeasurementsArgument,
        train: TrainWindowOption,
        test: TestWindowOption,
        name: NameOption = None,
        seed: SeedOption = 0,
        as_json: JsonOption = False,
        plots: PlotsOption = Path("graphtwin-plots"),
        only_when: OnlyWhenOption = None,
        start_from: StartFromOption = None,
        store: StoreOption = Path("graphtwin-data"),
        memory: MemoryOption = False,
    ) -> None:
        _diagnose_cli(model, data, train, test, name, seed, as_json, plots, store, memory, rank_effects=rank_effects,
                      only_when=only_when, start_from=start_from)

    command.__doc__ = doc
    return command


app.command("diagnose")(_diagnosis_command(
    True, "Calibrate on TRAIN, compare on TEST, locate the failures and rank the missing effects."))
app.command("compare")(_diagnosis_command(
    False, "Calibrate on TRAIN, compare on TEST and locate the failures (sensor, flow path, regime, time), "
           "without testing the effect catalog: the diagnosis' first two steps, in seconds."))


@app.command("compare-strategies")
def compare_strategies_command(
    model: ModelFileArgument,
    data: MeasurementsArgument,
    train: TrainWindowOption = "/",
    test: TestWindowOption = None,
    folds: Annotated[int, typer.Option(help="Held-out blocks of the training window for cross-validation.")] = 3,
    name: NameOption = None,
    seed: SeedOption = 0,
    as_json: JsonOption = False,
    store: StoreOption = Path("graphtwin-data"),
    memory: MemoryOption = False,
) -> None:
    """Joint against successive (regime by regime, Morris-planned) point calibration on TRAIN: RMSE
    and R² per operating regime and a blocked cross-validation, so you see which converges better.
    Nothing is written to the store."""
    from service.calibration.run import parse_window
    from service.calibration.successive import compare_calibration_strategies

    graph_store = open_store(store, memory)
    try:
        model_name = _load(graph_store, model, name)
        comparison = compare_calibration_strategies(graph_store, model_name, data, train=parse_window(train),
                                                    test=parse_window(test) if test else None, n_folds=folds,
                                                    seed=seed)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    if as_json:
        console.print_json(json.dumps(comparison.to_dict(), default=str))
        return
    console.print(comparison.table(), markup=False, highlight=False, soft_wrap=True)  # a text table: no breaks inside numbers


@app.command("add-effect")
def add_effect_command(
    model: ModelFileArgument,
    effect: Annotated[str, typer.Option(help="Effect signature id, e.g. FanMotorHeat.")],
    target: Annotated[str, typer.Option(help="IRI of the building node the effect applies to.")],
    output: Annotated[Path, typer.Option("-o", "--output", help=(
        "Where to write the new model, in the format of its suffix (.ttl, .nt, .rdf, .jsonld)."))],
) -> None:
    """Record EFFECT at TARGET in the semantic model (as triples); re-assembly picks it up."""
    library = SignatureLibrary.load()
    signature = library.get(effect)
    if signature is None or signature.kind != "effect":
        raise fail(f"no effect {effect!r}; the catalog has {', '.join(sorted(s.id for s in library.values() if s.kind == 'effect'))}")
    check = GraphStore.embedded(None)
    try:
        _load(check, model, "check")
        assemble(check, "check", library=library, extra_effects=[EffectRequest(effect, target)])  # it applies there
        recorded = applied_effect_triples(signature, target)
        if recorded[0] in check.graph_triples(check.model_graph("check")):
            raise fail(f"{effect} is recorded at {target} in {model} already: nothing to add")
        record_effect_in_file(model, output, recorded)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    console.print(f"{effect} recorded at {target} in {output}")


@example_app.command("list")
def example_list() -> None:
    """The example building models shipped with graphtwin."""
    for folder in sorted(p for p in examples_dir().iterdir() if (p / "model.ttl").is_file()):
        console.print(f"{folder.name:28s} {folder / 'model.ttl'}")


@example_app.command("generate")
def example_generate(
    name: Annotated[str, typer.Argument(help="Example model (see `graphtwin example list`) or a model file.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="CSV to write.")],
    hidden_effect: Annotated[str | None, typer.Option(help="Effect hidden in the truth (none: a truth the base model can match).")] = None,
    node: Annotated[str | None, typer.Option(help="Where to hide it (default: the first node it applies to).")] = None,
    seed: SeedOption = 0,
    days: Annotated[float, typer.Option(help="Length of the data, days (without --operation).")] = 7.0,
    operation: Annotated[Path | None, typer.Option(help=(
        "A measurement CSV of the model whose boundary inputs (and time grid) drive the truth: real "
        "operation, known truth (semi-synthetic data)."))] = None,
    truth_from: Annotated[Path | None, typer.Option(help=(
        "JSON of a calibration (`graphtwin calibrate --json`): its medians are the truth's parameters "
        "(the others drawn as without it)."))] = None,
    truth_json: Annotated[Path | None, typer.Option(help=(
        "Write the truth here (JSON: the hidden effect, where, and every parameter as `calibrate --json` "
        "gives it, so --truth-from reads it back): what a calibration of the data should find."))] = None,
) -> None:
    """Synthetic measurements for a model from a known truth, optionally with a hidden effect."""
    from service.data.synthetic import generate_synthetic_data

    is_file = Path(name).is_file()
    path = Path(name) if is_file else examples_dir() / name / "model.ttl"
    if not path.is_file():
        raise fail(f"no example or model file {name!r}; see `graphtwin example list`")
    store = GraphStore.embedded(None)
    try:
        truth = _medians(truth_from) if truth_from is not None else None
        model_name = _load(store, path, None if is_file else name)
        generated = generate_synthetic_data(
            store, model_name, output, library=SignatureLibrary.load(), hidden_effect=hidden_effect,
            node=node, seed=seed, n_days=days, operation=operation, truth=truth)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    if truth_json is not None:
        truth_json.write_text(json.dumps({
            "hidden_effect": generated.effect, "node": generated.node,
            "parameters": {key: {"median": value} for key, value in generated.theta.items()}}, indent=1) + "\n")
    where = f" at {generated.node}" if generated.node else ""
    driven = f"the operation of {operation}" if operation is not None else f"{days:g} days of synthetic operation"
    given = f", {len(truth)} parameters from {truth_from}" if truth else ""
    console.print(f"wrote {output} ({driven}) from a truth with {generated.effect or 'no hidden effect'}{where}{given}")


def _medians(calibration_json: Path) -> dict[str, float]:
    """Parameter key → median, from the JSON ``graphtwin calibrate --json`` prints."""
    try:
        parameters = json.loads(calibration_json.read_text(encoding="utf-8"))["parameters"]
        return {key: float(estimate["median"]) for key, estimate in parameters.items()}
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{calibration_json}: not the JSON of `graphtwin calibrate --json` ({exc})") from None


@app.command("query")
def query_command(
    name: Annotated[str, typer.Argument(help="A query in queries/ (file name without .rq).")],
    model: Annotated[str | None, typer.Option(help=(
        "The model: bound to ?model in a query about results; the graphs a query about a building graph runs over."))] = None,
    param: Annotated[list[str] | None, typer.Option(help="More bindings, VAR=VALUE.")] = None,
    output_format: Annotated[str | None, typer.Option(
        "--format", help="table, csv or json (full IRIs); default: a table on a terminal, CSV when piped.")] = None,
    store: StoreOption = Path("graphtwin-data"),
) -> None:
    """Run a named SPARQL query over the store (e.g. calibrated-parameters --model NAME). A query that
    names no graph (flow-edges, observed-node, measurement-link, applied-effects) reads a building
    model: it runs over the model's graphs (model, inferences, ontologies); one about results binds
    ?model to the name, and ?model_graph, ?inferred_graph, ?ontology_graph where it reads them."""
    output_format = output_format or ("table" if console.is_terminal else "csv")
    if output_format not in ("table", "csv", "json"):
        raise fail(f"--format {output_format!r}: give table, csv or json")
    graph_store = open_store(store, False, reading=True)
    if model is not None and model not in graph_store.models():
        raise fail(f"no model {model!r} in the store {store}; it holds {', '.join(graph_store.models()) or 'none'}")
    try:
        text = graph_store.named_query_text(name)
        reads_a_model = not re.search(r"^[^#]*\bGRAPH\b", text, re.IGNORECASE | re.MULTILINE)  # outside comments
        if reads_a_model and model is None:
            raise fail(f"query {name} reads a building model's graphs: give --model")
        bindings = dict(_binding(p) for p in (param or []))
        if model is not None and not reads_a_model:
            bindings |= {"model": model} | {var: iri for var, iri in graph_store.graph_variables(model).items()
                                            if f"?{var}" in text}
        rows = graph_store.run_named_query(name, dataset=model if reads_a_model else None, **bindings)
    except USER_ERRORS as exc:
        raise fail(exc) from None
    columns = list(dict.fromkeys(k for row in rows for k in row))
    values = [{c: row[c].value for c in columns if c in row} for row in rows]
    if output_format == "json":
        sys.stdout.write(json.dumps(values, indent=1) + "\n")
    elif output_format == "csv":
        writer = csv.DictWriter(sys.stdout, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(values)
    else:
        table = Table(title=f"{name} ({len(rows)} rows)")
        for column in columns:
            table.add_column(column, overflow="fold")
        for row in values:
            table.add_row(*[local_name(v) if v.startswith("http") else v for v in (row.get(c, "") for c in columns)])
        console.print(table)


def _binding(text: str) -> tuple[str, str]:
    """``VAR=VALUE`` → (var, value). :raises ValueError: without ``=``."""
    var, equals, value = text.partition("=")
    if not equals or not var:
        raise ValueError(f"--param {text!r}: write VAR=VALUE")
    return var, value


@app.command("history")
def history_command(
    model: Annotated[str, typer.Argument(help="Model name in the store.")],
    plot: Annotated[Path | None, typer.Option(help="Write a bar chart of the error per version here (PNG).")] = None,
    store: StoreOption = Path("graphtwin-data"),
) -> None:
    """Test-window error per sensor and operating regime across the versions of a model (base,
    base+effect, …)."""
    from service.diagnosis.error_history import error_history

    graph_store = open_store(store, False, reading=True)
    history = error_history(graph_store, model)
    if not history.versions:
        raise fail(f"no calibration with a test window for model {model!r} or its versions")
    table = Table(title=f"Test RMSE per sensor across versions of {model}")
    table.add_column("sensor")
    for version in history.versions:
        table.add_column(version)
    for sensor, values in history.rmse.items():
        table.add_row(local_name(sensor), *[_with_unit(v, history.units[sensor]) for v in values])
    table.add_row("tested on", *history.tested_on, style="dim")
    console.print(table)
    if not history.comparable:
        error_console.print("[yellow]warning:[/yellow] the versions were tested on different data or windows: their "
                            "errors differ by that as much as by the model; calibrate them on the same test window")
    if history.regime_rmse:
        table = Table(title="Test RMSE per operating regime (share of the test window)")
        for column in ("regime", "rule", "sensor", *history.versions):
            table.add_column(column)
        for number, (rule, sensors) in enumerate(history.regime_rmse.items()):
            shares = history.regime_share[rule]
            share = next((f" ({100 * s:.0f} %)" for s in shares if s == s), "")
            for i, (sensor, values) in enumerate(sensors.items()):
                table.add_row(str(number) if i == 0 else "", rule + share if i == 0 else "", local_name(sensor),
                              *[_with_unit(v, history.units.get(sensor, "")) for v in values])
            table.add_section()
        console.print(table)
    if plot is not None:
        from service.report.plots import plot_error_history

        console.print(f"plot: {plot_error_history(plot, history)}")


#: A parameter key (``<component IRI>#<name>``) in a sentence, read as ``<component's node>.<name>``.
_PARAMETER_KEY = re.compile(r"\S*/component/[^/\s]+/([^\s/#]+)#(\w+)")


def _with_unit(value: float, unit: str) -> str:
    return f"{value:.3g} {unit_label(unit)}" if value == value else "–"


@app.command("report")
def report_command(
    run: Annotated[str, typer.Argument(help="Run id (printed by calibrate and diagnose; \"run\" in diagnose --json).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="HTML file to write.")] = Path("report.html"),
    data: Annotated[Path | None, typer.Option(help="The run's measurement CSV (default: the file name the run "
                                                   "recorded, in the current folder).")] = None,
    store: StoreOption = Path("graphtwin-data"),
) -> None:
    """One self-contained HTML page for RUN: measured vs model per sensor, where it fails on the flow
    topology, the operating regimes, the missing effects with their evidence, the error across versions."""
    from service.report.page import UnknownRunError, data_file_locator, report_html

    if data is not None and not data.is_file():
        raise fail(f"{data}: no such file")
    graph_store = open_store(store, False, reading=True)
    locate, missing = data_file_locator(data), []

    def locate_noting(source: str) -> Path:
        try:
            return locate(source)
        except FileNotFoundError as exc:
            missing.append(str(exc))
            raise

    try:
        page = report_html(graph_store, run, locate_data=locate_noting)
    except UnknownRunError as exc:
        raise fail(exc) from None
    output.write_text(page, encoding="utf-8")
    console.print(f"wrote {output}")
    for problem in dict.fromkeys(missing):
        console.print(f"[yellow]warning:[/] {problem}: the page has no measured-vs-model plots", markup=True)


@app.command("demo")
def demo_command(
    hidden_effect: Annotated[str, typer.Option(help="The effect hidden in the synthetic truth.")] = "FanMotorHeat",
    seed: SeedOption = 1,
    output: Annotated[Path, typer.Option(help="Folder for the data, the new model and the plots.")] = Path("graphtwin-demo"),
    store: StoreOption = Path("graphtwin-data"),
) -> None:
    """The whole loop on the case study with a hidden effect: before, where it fails, what is missing, after."""
    from service.calibration.run import calibrate
    from service.diagnosis.loop import diagnose
    from service.diagnosis.error_history import error_history
    from service.report.plots import plot_error_history, plot_measured_vs_model
    from service.data.synthetic import generate_synthetic_data

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    output.mkdir(parents=True, exist_ok=True)
    graph_store = open_store(store, False)
    library = SignatureLibrary.load()
    base_name = "ventilation_case_study"
    model_path = examples_dir() / base_name / "model.ttl"
    graph_store.load_model(base_name, model_path)
    data = output / "measurements.csv"
    truth = generate_synthetic_data(graph_store, base_name, data, library=library, hidden_effect=hidden_effect, seed=seed)
    train, test = ("2026-01-12", "2026-01-15T23:59"), ("2026-01-16", None)
    console.rule("[bold]1. The data")
    console.print(f"One week of 10-minute data for the paper's ventilation unit ({data}), simulated from a truth "
                  f"with a hidden effect the base model lacks. Train: first 4 days; test: last 3.")
    console.rule("[bold]2. Calibrate the base model, compare, diagnose")
    report = diagnose(graph_store, base_name, data, train=train, test=test, seed=seed,
                      on_progress=lambda m: console.print(f"[dim]{m}…[/dim]"))
    _print_diagnosis(report)
    if not report.significant:
        console.print("No effect is significant: nothing to add.")
        return
    best = report.significant[0]
    console.rule(f"[bold]3. Add {best.effect} at {local_name(best.node)} and recalibrate from the base fit")
    new_model = output / "model_with_effect.ttl"
    record_effect_in_file(model_path, new_model, applied_effect_triples(library[best.effect], best.node))
    version = f"{base_name}+{best.effect}"
    graph_store.load_model(version, new_model)
    before = report.sensors
    after_run = calibrate(graph_store, version, data, train=train, test=test, seed=seed, start_from=base_name)
    table = Table(title="Test-window RMSE: before and after")
    for column in ("sensor", "before", "after", "change"):
        table.add_column(column)
    for node, metrics in after_run.record.metrics["test"].items():
        old = before[node]["rmse"]
        table.add_row(local_name(node), f"{old:.3g}", f"{metrics.rmse:.3g} {unit_label(metrics.unit)}",
                      f"{100 * (metrics.rmse - old) / old:+.0f} %")
    console.print(table)
    estimate = next((e for e in after_run.record.estimates if f"/{best.effect}/" in e.component), None)
    if estimate is not None:
        console.print(f"{best.effect}: {estimate.name} = {estimate.median:.3g} (16–84 %: {estimate.quantile16:.3g} – "
                      f"{estimate.quantile84:.3g}); the truth hid {truth.effect} at {local_name(truth.node or '')}.")
    md = after_run.model_data
    window = after_run.test
    figure = plot_measured_vs_model(output / "before_after.png", md.data.timestamps[window], md.observed(window),
                                    {"base model": report.base_test_prediction, f"with {best.effect}": after_run.predictions["test"]},
                                    md.units, title="Test window: measured, base model, model with the effect")
    history = plot_error_history(output / "error_history.png", error_history(graph_store, base_name))
    console.rule("[bold]4. Where to look")
    console.print(f"plots: {figure}, {history}")
    console.print(f"calibrated parameters by SPARQL: graphtwin query calibrated-parameters --model {version} --store {store}")


@app.command("serve")
def serve_command(
    store: Annotated[Path | None, typer.Option("--store", help="Embedded store folder (default ./graphtwin-data, "
                                                               "or GRAPHTWIN_STORE_DIR).")] = None,
    sparql_endpoint: Annotated[str | None, typer.Option("--sparql-endpoint", help="Use this SPARQL 1.1 endpoint "
                                                        "(Oxigraph server layout) instead of an embedded store.")] = None,
    data_dir: Annotated[Path | None, typer.Option("--data-dir", help="Job records and measurement uploads "
                                                  "(default ./graphtwin-service, or GRAPHTWIN_DATA_DIR).")] = None,
    host: Annotated[str, typer.Option(help="Interface to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port.")] = 8000,
) -> None:
    """Run the HTTP service (OpenAPI at /docs). Writes need the bearer token in GRAPHTWIN_TOKEN; the
    other settings come from GRAPHTWIN_* variables (service/settings.py)."""
    import uvicorn
    from pydantic import ValidationError

    from service.http.app import create_app
    from service.settings import Settings

    if store is not None and sparql_endpoint is not None:
        raise fail("give --store or --sparql-endpoint, not both")
    overrides = {"store_dir": store, "sparql_endpoint": sparql_endpoint, "data_dir": data_dir}
    try:
        settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        raise fail(exc) from None
    if settings.store_dir is None and settings.sparql_endpoint is None:
        settings = settings.model_copy(update={"store_dir": Path("graphtwin-data")})
    if settings.token is None:
        error_console.print("[yellow]GRAPHTWIN_TOKEN is not set: every write will be refused.[/yellow]")
    uvicorn.run(create_app(settings), host=host, port=port)
