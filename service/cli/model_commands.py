"""Commands about a building model: assemble it, report what the Brick alignment could not use,
inspect the signature library, record an effect, simulate it, and make example data."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.syntax import Syntax
from rich.table import Table

from service.cli.common import (
    DEFAULT_STORE,
    JsonOption,
    MemoryOption,
    ModelFileArgument,
    NameOption,
    SeedOption,
    StoreOption,
    app,
    console,
    example_app,
    loaded_model_file,
    open_store,
    reports_errors,
    signature_app,
)
from service.components.library import SignatureLibrary
from service.errors import GraphtwinError, InputError, NotFoundError
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.graph.units import difference_label
from service.graph.vocabulary import with_term_locations
from service.matching.compiler import compile_signature
from service.model.summary import assembly_to_dict, print_assembly
from service.resources import examples_dir
from service.workflows.effects import add_effect_to_file

__all__ = []


@app.command("assemble")
@reports_errors
def assemble_command(
    model: ModelFileArgument,
    name: NameOption = None,
    max_complexity: Annotated[int | None, typer.Option(help="Ignore signatures above this complexity.")] = None,
    as_json: JsonOption = False,
    store: StoreOption = DEFAULT_STORE,
    memory: MemoryOption = False,
) -> None:
    """Load MODEL into the store, assemble its simulation model and write it back as triples."""
    from service.report.brick import brick_report
    from service.workflows.runs import assemble_model  # with the calibration floor: loaded by the command, not --help

    graph_store = open_store(store, memory)
    with loaded_model_file(graph_store, model, name) as model_name:
        try:
            assembled = assemble_model(graph_store, model_name, max_complexity=max_complexity)
        except GraphtwinError as exc:
            if not brick_report(graph_store, model_name).is_brick:
                raise
            raise InputError(f"{exc}\n{model} is a Brick model: graphtwin brick-report {model} lists what the "
                             "alignment could not use") from None
    assembled.notes = tuple(with_term_locations(assembled.notes, model.read_text(encoding="utf-8", errors="replace"),
                                                model.name))  # a misspelt term: where the file uses it
    if as_json:
        console.print_json(json.dumps(assembly_to_dict(assembled)))
    else:
        print_assembly(assembled, console)


@app.command("brick-report")
@reports_errors
def brick_report_command(
    model: Annotated[Path, typer.Argument(help="Building model file (Brick 1.3/1.4).")],
    name: NameOption = None,
    brick_ontology: Annotated[Path | None, typer.Option(help=(
        "The official Brick ontology file (Brick.ttl): tells an official class graphtwin does not model "
        "from a misspelt one."))] = None,
    as_json: JsonOption = False,
    store: StoreOption = DEFAULT_STORE,
    memory: MemoryOption = False,
) -> None:
    """What the Brick alignment could not use in MODEL: unaligned classes, unread relations, the
    assumptions it made and the triples that would remove them, points without a column or unit."""
    from service.report.brick import brick_report, official_brick_classes, print_brick_report

    graph_store = open_store(store, memory)
    official = official_brick_classes(brick_ontology) if brick_ontology is not None else None
    with loaded_model_file(graph_store, model, name) as model_name:
        report = brick_report(graph_store, model_name, official)
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
@reports_errors
def signature_explain(name: Annotated[str, typer.Argument(help="Signature id, e.g. Fan.")]) -> None:
    """Print the SPARQL query a signature compiles to (highlighted on a terminal; the text as it is
    when written to a file or a pipe, so 'graphtwin signature explain Fan > fan.rq' is a query any
    endpoint runs)."""
    library = SignatureLibrary.load()
    if name not in library:
        raise NotFoundError(f"no signature {name!r}; known: {', '.join(sorted(library))}")
    text = compile_signature(library[name]).text
    if console.is_terminal:
        console.print(Syntax(text, "sparql", word_wrap=True))
    else:
        sys.stdout.write(text)


@app.command("add-effect")
@reports_errors
def add_effect_command(
    model: ModelFileArgument,
    effect: Annotated[str, typer.Option(help="Effect signature id, e.g. FanMotorHeat.")],
    target: Annotated[str, typer.Option(help="IRI of the building node the effect applies to.")],
    output: Annotated[Path, typer.Option("-o", "--output", help=(
        "Where to write the new model, in the format of its suffix (.ttl, .nt, .rdf, .jsonld)."))],
) -> None:
    """Record EFFECT at TARGET in the semantic model (as triples); re-assembly picks it up."""
    add_effect_to_file(model, output, effect, target, SignatureLibrary.load())
    console.print(f"{effect} recorded at {target} in {output}")


@app.command("simulate")
@reports_errors
def simulate_command(
    model: ModelFileArgument,
    data: Annotated[Path, typer.Argument(help="Measurement CSV (boundary inputs; targets optional for comparison).")],
    params: Annotated[Path | None, typer.Option(help="JSON {parameter name or key: value}; others at their defaults.")] = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="CSV of measured and simulated series.")] = None,
    name: NameOption = None,
    store: StoreOption = DEFAULT_STORE,
    memory: MemoryOption = False,
) -> None:
    """Simulate MODEL over DATA and write each target's simulation beside its measurement."""
    from service.calibration.model_data import ModelData
    from service.data.csv_output import write_comparison_csv
    from service.data.model_series import read_model_data
    from service.model.assembly import assemble
    from service.model.simulator import loop_substeps, target_series

    graph_store = open_store(store, memory)
    with loaded_model_file(graph_store, model, name) as model_name:
        assembled = assemble(graph_store, model_name)
        measured = read_model_data(assembled, data)
        try:
            values = json.loads(params.read_text()) if params is not None else {}
        except json.JSONDecodeError as exc:
            raise InputError(f"{params}: not JSON ({exc})") from None
        refs = assembled.estimated_parameters
        known = {r.key for r in refs} | {r.name for r in refs}
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(f"{params}: no estimated parameter named {', '.join(unknown)}")
    theta = [float(values.get(r.key, values.get(r.name, r.spec.default))) for r in refs]
    md = ModelData(assembled, measured, loop_substeps(assembled, measured.step_s))
    result = md.simulate_all(slice(0, measured.n_steps), np.array(theta))
    simulated = target_series(assembled, result)
    if output is not None:
        write_comparison_csv(output, measured, simulated)
        console.print(f"wrote {output}")
    table = Table(title="Simulated against measured")
    for column in ("sensor", "RMSE", "unit"):
        table.add_column(column, overflow="fold")
    for node, values in simulated.items():
        observed = measured.series[node]
        finite = np.isfinite(observed)
        rmse = float(np.sqrt(np.mean((observed[finite] - values[finite]) ** 2))) if finite.any() else float("nan")
        table.add_row(local_name(node), f"{rmse:.3g}", difference_label(measured.units[node]))
    console.print(table)


@example_app.command("list")
def example_list() -> None:
    """The example building models shipped with graphtwin."""
    for folder in sorted(p for p in examples_dir().iterdir() if (p / "model.ttl").is_file()):
        console.print(f"{folder.name:28s} {folder / 'model.ttl'}")


@example_app.command("generate")
@reports_errors
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
        "Write the truth here (JSON: the hidden effect, where, and each parameter's value as the median under "
        "the key `calibrate --json` uses, in the parameter's unit, so --truth-from reads it back): what a "
        "calibration of the data should find."))] = None,
) -> None:
    """Synthetic measurements for a model from a known truth, optionally with a hidden effect."""
    from service.data.synthetic import generate_synthetic_data

    is_file = Path(name).is_file()
    path = Path(name) if is_file else examples_dir() / name / "model.ttl"
    if not path.is_file():
        raise NotFoundError(f"no example or model file {name!r}; see `graphtwin example list`")
    store = GraphStore.embedded(None)
    truth = _medians(truth_from) if truth_from is not None else None
    with loaded_model_file(store, path, None if is_file else name) as model_name:
        generated = generate_synthetic_data(
            store, model_name, output, library=SignatureLibrary.load(), hidden_effect=hidden_effect,
            node=node, seed=seed, n_days=days, operation=operation, truth=truth)
    if truth_json is not None:
        truth_json.write_text(json.dumps({
            "hidden_effect": generated.effect, "node": generated.node,
            "parameters": {key: {"median": value} for key, value in generated.theta.items()}}, indent=1) + "\n")
    where = f" at {generated.node}" if generated.node else ""
    driven = f"the operation of {operation}" if operation is not None else f"{days:g} days of synthetic operation"
    given = f", {len(truth)} parameters from {truth_from}" if truth else ""
    console.print(f"wrote {output} ({driven}) from a truth with {generated.effect or 'no hidden effect'}{where}{given}")


def _medians(calibration_json: Path) -> dict[str, float]:
    """Parameter key → median, from the JSON ``graphtwin calibrate --json`` prints.

    :raises InputError: the file is not that JSON.
    """
    try:
        parameters = json.loads(calibration_json.read_text(encoding="utf-8"))["parameters"]
        return {key: float(estimate["median"]) for key, estimate in parameters.items()}
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{calibration_json}: not the JSON of `graphtwin calibrate --json` ({exc})") from None
