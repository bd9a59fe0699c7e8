"""Commands that fit a model to measurements (calibrate, compare, diagnose, compare-strategies)
and prepare them (data block-means)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from service.cli.common import (
    DEFAULT_STORE,
    JsonOption,
    MeasurementsArgument,
    MemoryOption,
    ModelFileArgument,
    NameOption,
    OnlyWhenOption,
    SeedOption,
    StartFromOption,
    StoreOption,
    TestWindowOption,
    TrainWindowOption,
    app,
    console,
    data_app,
    error_console,
    loaded_model_file,
    open_store,
    reports_errors,
)
from service.cli.printing import print_calibration, print_data_warnings, print_diagnosis, save_diagnosis_plots
from service.data.windows import parse_window
from service.workflows.requests import CalibrateRequest, DiagnoseRequest, checked_request

__all__ = []


@app.command("calibrate")
@reports_errors
def calibrate_command(
    model: ModelFileArgument,
    data: MeasurementsArgument,
    train: TrainWindowOption = "/",
    test: TestWindowOption = None,
    method: Annotated[str, typer.Option(help="point (least squares) or bayes (KOH, PT-MCMC: minutes, not seconds; "
                                             "docs/calibration.md).")] = "point",
    name: NameOption = None,
    seed: SeedOption = 0,
    plots: Annotated[Path | None, typer.Option(help="Folder for the plots: <run id>-fit.png (measured vs model), "
                                                    "for --method bayes -trace.png and -corner.png too.")] = None,
    only_when: OnlyWhenOption = None,
    gp_input: Annotated[list[str] | None, typer.Option(
        help="An input of the discrepancy GP (--method bayes): 'time' (the default) or a boundary input "
             "(node local name, IRI or CSV column); repeat for several.")] = None,
    max_steps: Annotated[int | None, typer.Option(
        help="The sampler's step limit (--method bayes; default 4000): a run not converged by then stops and "
             "says so.")] = None,
    start_from: StartFromOption = None,
    as_json: JsonOption = False,
    store: StoreOption = DEFAULT_STORE,
    memory: MemoryOption = False,
) -> None:
    """Calibrate MODEL against DATA; estimates, metrics and provenance are written to the store."""
    from service.workflows.runs import calibrate_model  # SciPy and scikit-learn load with the command, not with --help

    graph_store = open_store(store, memory, start_from=start_from)
    with loaded_model_file(graph_store, model, name) as model_name:
        request = checked_request(CalibrateRequest, model=model_name, measurements=str(data), train=train, test=test,
                                  method=method, seed=seed, only_when=only_when or [],
                                  gp_inputs=gp_input or None, start_from=start_from, max_steps=max_steps)
        # the bar shows on a terminal; written to a file or a pipe, each convergence check is a line (on stderr
        # beside --json, whose stdout is the JSON alone: a half-hour run had been silent)
        said = (None if console.is_terminal and not as_json else
                (lambda m: (error_console if as_json else console).print(f"{m}…", markup=False)))
        outcome = calibrate_model(graph_store, request, data, progress=not as_json, on_progress=said)
    if plots is not None:  # the fit, and a Bayesian run's trace and corner plots (docs/report.md)
        from service.report.calibration_plots import plot_calibration

        plot_calibration(outcome, plots)
    if as_json:
        console.print_json(json.dumps(outcome.record.to_dict(), default=str))
    else:
        print_calibration(outcome.record, outcome.model_data.data.source_units)


PlotsOption = Annotated[Path, typer.Option(help="Folder for the plots (text output only).")]


def _diagnosis_command(rank_effects: bool, doc: str):
    """The ``diagnose`` (``rank_effects``) or ``compare`` command: the same options, the same report."""

    @reports_errors
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
        store: StoreOption = DEFAULT_STORE,
        memory: MemoryOption = False,
    ) -> None:
        from service.workflows.runs import diagnose_model

        graph_store = open_store(store, memory, start_from=start_from)
        with loaded_model_file(graph_store, model, name) as model_name:
            request = checked_request(DiagnoseRequest, model=model_name, measurements=str(data), train=train,
                                      test=test, seed=seed, only_when=only_when or [], start_from=start_from)
            report = diagnose_model(graph_store, request, data, rank_effects=rank_effects,
                                    on_progress=None if as_json else (lambda m: console.print(f"[dim]{m}…[/dim]")))
        if as_json:
            console.print_json(json.dumps(report.to_dict(), default=str))
            return
        print_diagnosis(report, stored=not memory, data=Path(data), store=store, model_file=Path(model))
        console.print("plots: " + ", ".join(str(p) for p in save_diagnosis_plots(report, plots)))

    command.__doc__ = doc
    return command


app.command("diagnose")(_diagnosis_command(
    True, "Calibrate on TRAIN, compare on TEST, locate the failures and rank the missing effects."))
app.command("compare")(_diagnosis_command(
    False, "Calibrate on TRAIN, compare on TEST and locate the failures (sensor, flow path, regime, time), "
           "without testing the effect catalog: the diagnosis' first two steps, in seconds."))


@app.command("compare-strategies")
@reports_errors
def compare_strategies_command(
    model: ModelFileArgument,
    data: MeasurementsArgument,
    train: TrainWindowOption = "/",
    test: TestWindowOption = None,
    folds: Annotated[int, typer.Option(help="Held-out blocks of the training window for cross-validation.")] = 3,
    name: NameOption = None,
    seed: SeedOption = 0,
    as_json: JsonOption = False,
    store: StoreOption = DEFAULT_STORE,
    memory: MemoryOption = False,
) -> None:
    """Joint against successive (regime by regime, Morris-planned) point calibration on TRAIN: RMSE
    and R² per operating regime and a blocked cross-validation, so you see which converges better.
    Nothing is written to the store."""
    from service.calibration.successive import compare_calibration_strategies

    graph_store = open_store(store, memory)
    with loaded_model_file(graph_store, model, name) as model_name:
        comparison = compare_calibration_strategies(graph_store, model_name, data, train=parse_window(train),
                                                    test=parse_window(test) if test else None, n_folds=folds,
                                                    seed=seed)
    if as_json:
        console.print_json(json.dumps(comparison.to_dict(), default=str))
        return
    console.print(comparison.table(), markup=False, highlight=False, soft_wrap=True)  # a text table: no breaks inside numbers


@data_app.command("block-means")
@reports_errors
def block_means_command(
    source: Annotated[Path, typer.Argument(help="Measurement CSV: a time column, then series (a BMS log).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="CSV to write (the same columns).")],
    minutes: Annotated[int, typer.Option(help="Block length: a whole multiple of the log's step.")] = 15,
    day: Annotated[list[str] | None, typer.Option(help="An ISO date to keep (repeat for several; default: all).")] = None,
) -> None:
    """Means over clock-aligned blocks of MINUTES, each stamped with its start, where the log covers
    the block whole (a 1-minute log as 15-minute means: how the FLEXLAB days are diagnosed)."""
    from service.data.block_means import write_block_means

    blocks = write_block_means(source, output, minutes, set(day) if day else None)
    console.print(f"wrote {output}: {blocks} blocks of {minutes} min")


@data_app.command("check")
@reports_errors
def data_check_command(
    model: ModelFileArgument,
    data: MeasurementsArgument,
    name: NameOption = None,
    store: StoreOption = DEFAULT_STORE,
    memory: MemoryOption = False,
) -> None:
    """Read DATA as MODEL needs it, without simulating: each measured device's column, unit and
    measured steps, and every problem or note (exit 2 naming each problem, with its line)."""
    from rich.table import Table

    from service.data.model_series import read_model_data
    from service.errors import MeasurementError
    from service.graph.namespaces import local_name
    from service.graph.units import quantity_text, unit_label
    from service.model.assembly import assemble

    graph_store = open_store(store, memory)
    with loaded_model_file(graph_store, model, name) as model_name:
        assembled = assemble(graph_store, model_name)
        measured = read_model_data(assembled, data)
    roles = {assembled.components[c].node: "boundary input" for c in assembled.boundary_inputs}
    roles |= {assembled.components[c].node: "target" for c in assembled.targets}
    table = Table(title=f"{data}: {measured.n_steps} steps of {measured.step_s:g} s, "
                        f"{measured.shown(measured.timestamps[0])} – {measured.shown(measured.timestamps[-1])}")
    for column in ("device", "role", "column", "unit: file → model", "measured steps", "range"):
        table.add_column(column, overflow="fold")
    for node, values in measured.series.items():
        unit, finite = measured.units[node], values[np.isfinite(values)]
        span = f"{quantity_text(finite.min(), unit)} – {quantity_text(finite.max(), unit)}" if finite.size else "–"
        table.add_row(local_name(node), roles.get(node, ""), measured.columns[node],
                      f"{unit_label(measured.source_units.get(node, unit)) or '1'} → {unit_label(unit) or '1'}",
                      f"{finite.size} of {values.size}", span)
    console.print(table)
    print_data_warnings([*assembled.notes, *measured.warnings])
    empty = [f"column {measured.columns[node]!r} ({local_name(node)}, {roles.get(node, 'measured')}) holds no number"
             for node, values in measured.series.items() if not np.isfinite(values).any()]
    if empty:
        raise MeasurementError(str(data), empty)
