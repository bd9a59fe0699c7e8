"""``graphtwin demo``: the whole loop on the case study with a hidden effect — the data, the base
model's fit and diagnosis, the effect added and recalibrated, the error before and after."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from service.cli.common import DEFAULT_STORE, SeedOption, StoreOption, app, console, open_store, reports_errors
from service.cli.printing import print_diagnosis
from service.components.library import SignatureLibrary
from service.graph.namespaces import local_name
from service.graph.units import difference_unit, quantity_text
from service.resources import examples_dir
from service.workflows.effects import add_effect_to_file
from service.workflows.requests import CalibrateRequest, DiagnoseRequest

__all__ = []


@app.command("demo")
@reports_errors
def demo_command(
    hidden_effect: Annotated[str, typer.Option(help="The effect hidden in the synthetic truth.")] = "FanMotorHeat",
    seed: SeedOption = 1,
    output: Annotated[Path, typer.Option(help="Folder for the data, the new model and the plots.")] = Path("graphtwin-demo"),
    store: StoreOption = DEFAULT_STORE,
) -> None:
    """The whole loop on the case study with a hidden effect: before, where it fails, what is missing, after."""
    from service.data.synthetic import generate_synthetic_data
    from service.diagnosis.drift import DriftEvidence
    from service.diagnosis.error_history import error_history
    from service.report.plots import plot_error_history, plot_measured_vs_model
    from service.workflows.runs import calibrate_model, diagnose_model

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    output.mkdir(parents=True, exist_ok=True)
    graph_store = open_store(store, False)
    library = SignatureLibrary.load()
    base_name = "ventilation_case_study"
    model_path = examples_dir() / base_name / "model.ttl"
    graph_store.load_model(base_name, model_path)
    data = output / "measurements.csv"
    truth = generate_synthetic_data(graph_store, base_name, data, library=library, hidden_effect=hidden_effect, seed=seed)
    train, test = "2026-01-12/2026-01-15T23:59", "2026-01-16/"
    console.rule("[bold]1. The data")
    console.print(f"One week of 10-minute data for the paper's ventilation unit ({data}), simulated from a truth "
                  f"with a hidden effect the base model lacks. Train: first 4 days; test: last 3.")
    console.rule("[bold]2. Calibrate the base model, compare, diagnose")
    diagnosis = DiagnoseRequest(model=base_name, measurements=str(data), train=train, test=test, seed=seed)
    report = diagnose_model(graph_store, diagnosis, data, on_progress=lambda m: console.print(f"[dim]{m}…[/dim]"))
    print_diagnosis(report, data=data)
    if not report.significant:
        console.print("No effect is significant: nothing to add.")
        return
    best = report.significant[0]
    if isinstance(best, DriftEvidence):
        console.print("The answer is a parameter that drifts, not an effect of the catalog: nothing to add.")
        return
    console.rule(f"[bold]3. Add {best.effect} at {local_name(best.node)} and recalibrate from the base fit")
    new_model = output / "model_with_effect.ttl"
    add_effect_to_file(model_path, new_model, best.effect, best.node, library)
    version = f"{base_name}+{best.effect}"
    graph_store.load_model(version, new_model)
    before = report.sensors
    calibration = CalibrateRequest(model=version, measurements=str(data), train=train, test=test, seed=seed,
                                   start_from=base_name)
    after_run = calibrate_model(graph_store, calibration, data)
    table = Table(title="Test-window RMSE: before and after")
    for column in ("sensor", "before", "after", "change"):
        table.add_column(column, overflow="fold")
    for node, metrics in after_run.record.metrics["test"].items():
        old = before[node].rmse
        error_unit = difference_unit(metrics.unit)
        table.add_row(local_name(node), quantity_text(old, error_unit), quantity_text(metrics.rmse, error_unit),
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
