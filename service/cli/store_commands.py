"""Commands that read the store or serve it: named queries, a model's error history, a run's report
page, the HTTP service."""

from __future__ import annotations

import csv
import json
import re
import sys
from pathlib import Path
from typing import Annotated

import pyoxigraph as ox
import typer
from rich.table import Table

from service.cli.common import DEFAULT_STORE, StoreOption, app, console, error_console, fail, open_store, reports_errors
from service.errors import InputError, NotFoundError
from service.graph.namespaces import GTR, local_name
from service.graph.store import GraphStore
from service.graph.units import quantity_text

__all__ = []


@app.command("query")
@reports_errors
def query_command(
    name: Annotated[str, typer.Argument(help="A query in queries/ (file name without .rq), or a SELECT query's "
                                             ".rq file of your own.")],
    model: Annotated[str | None, typer.Option(help=(
        "The model: bound to ?model in a query about results; the graphs a query about a building graph runs over."))] = None,
    param: Annotated[list[str] | None, typer.Option(help="More bindings, VAR=VALUE.")] = None,
    output_format: Annotated[str | None, typer.Option(
        "--format", help="table, csv or json (full IRIs); default: a table on a terminal, CSV when piped.")] = None,
    store: StoreOption = DEFAULT_STORE,
) -> None:
    """Run a named SPARQL query over the store (e.g. calibrated-parameters --model NAME), or a SELECT
    query of your own (a .rq file). A query that names no graph (flow-edges, observed-node,
    measurement-link, applied-effects) reads a building model: it runs over the model's graphs (model,
    inferences, ontologies); one about results binds ?model to the name, and ?model_graph,
    ?inferred_graph, ?ontology_graph where it reads them."""
    output_format = output_format or ("table" if console.is_terminal else "csv")
    if output_format not in ("table", "csv", "json"):
        raise InputError(f"--format {output_format!r}: give table, csv or json")
    graph_store = open_store(store, False, reading=True)
    if model is not None and model not in graph_store.models() and not graph_store.has_results(model):
        raise NotFoundError(f"no model {model!r} in the store {store}; it holds {', '.join(graph_store.models()) or 'none'}")
    own = name.endswith(".rq") or "/" in name
    if own and not Path(name).is_file():
        raise NotFoundError(f"{name}: no such file")
    text = Path(name).read_text(encoding="utf-8") if own else graph_store.named_query_text(name)
    reads_a_model = not re.search(r"^[^#]*\bGRAPH\b", text, re.IGNORECASE | re.MULTILINE)  # outside comments
    if reads_a_model and model is None:
        try:  # a syntax error is the problem to name first
            GraphStore.embedded(None).query(text)
        except InputError as exc:
            raise InputError(f"{name}: {exc}") from None
        raise InputError(f"query {name} reads a building model's graphs: give --model")
    bindings = dict(_binding(p) for p in (param or []))
    if model is not None and not reads_a_model:
        bindings |= graph_store.result_bindings(model, text)
    try:
        rows = graph_store.query(text, substitutions=bindings, model=model if reads_a_model else None)
    except InputError as exc:
        raise InputError(f"{name}: {exc}") from None
    if not isinstance(rows, list) or rows and not isinstance(rows[0], dict):
        raise InputError(f"{name}: not a SELECT query (ASK, CONSTRUCT and DESCRIBE are not shown as a table)")
    columns = list(dict.fromkeys([*_projected(text), *(k for row in rows for k in row)]))
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
        for row in rows:
            table.add_row(*[_table_cell(row[c]) if c in row else "" for c in columns])
        console.print(table)


#: Literal datatypes a table shows to six significant digits (CSV and JSON keep every digit).
_DECIMALS = {f"http://www.w3.org/2001/XMLSchema#{t}" for t in ("double", "float", "decimal")}


def _table_cell(term) -> str:
    """A query result's term as a table shows it: an IRI by its local name (a run's result, whose
    local names repeat from run to run, by its path after ``gtr:run/``: ``case-point-1a2b/diagnosis``),
    a floating-point number to six significant digits, anything else as written."""
    value = term.value
    if isinstance(term, ox.Literal) and term.datatype.value in _DECIMALS:
        try:
            return f"{float(value):.6g}"
        except ValueError:
            return value
    if value.startswith(RUN_RESULTS):
        return value[len(RUN_RESULTS):]
    return local_name(value) if value.startswith("http") else value


#: Where a calibration run's results are named (``service.calibration.triples.run_iri``).
RUN_RESULTS = f"{GTR}run/"


def _projected(query: str) -> list[str]:
    """The variables a SELECT query projects, in order (``(expr AS ?x)`` gives x; ``SELECT *`` none):
    the columns of a result with no rows, which has no row to name them."""
    text = re.sub(r"#[^\n]*", "", query)  # comments (an IRI's # is rare in a projection)
    found = re.search(r"\bSELECT\s+(?:DISTINCT\s+|REDUCED\s+)?(.*?)(?:(?<![?$\w])(?:WHERE|FROM)\b|\{)", text,
                      re.IGNORECASE | re.DOTALL)
    if found is None:
        return []
    projection = re.sub(r"\((?:[^()]|\([^()]*\))*?\bAS\s+\?(\w+)\s*\)", r"?\1", found.group(1), flags=re.IGNORECASE)
    return re.findall(r"[?$](\w+)", projection)


def _binding(text: str) -> tuple[str, str]:
    """``VAR=VALUE`` → (var, value). :raises InputError: without ``=``."""
    var, equals, value = text.partition("=")
    if not equals or not var:
        raise InputError(f"--param {text!r}: write VAR=VALUE")
    return var, value


@app.command("history")
@reports_errors
def history_command(
    model: Annotated[str, typer.Argument(help="Model name in the store.")],
    plot: Annotated[Path | None, typer.Option(help="Write a bar chart of the error per version here (PNG).")] = None,
    store: StoreOption = DEFAULT_STORE,
) -> None:
    """Test-window error per sensor and operating regime across the versions of a model (base,
    base+effect, …)."""
    from service.diagnosis.error_history import error_history

    graph_store = open_store(store, False, reading=True)
    history = error_history(graph_store, model)
    if not history.versions:
        raise NotFoundError(f"no calibration with a test window for model {model!r} or its versions")
    table = Table(title=f"Test RMSE per sensor across versions of {model}")
    table.add_column("sensor", overflow="fold")
    for version in history.versions:
        table.add_column(version, overflow="fold")  # names differ at their end: model+Effect
    for sensor, values in history.rmse.items():
        table.add_row(local_name(sensor), *[quantity_text(v, history.units[sensor]) for v in values])
    table.add_row("tested on", *history.tested_on, style="dim")
    console.print(table)
    if not history.comparable:
        error_console.print("[yellow]warning:[/yellow] the versions were tested on different data, windows or "
                            "operating filters: their errors differ by that as much as by the model; calibrate them "
                            "on the same test window")
    if history.regime_rmse:
        table = Table(title="Test RMSE per operating regime (share of the test window)")
        for column in ("regime", "rule", "sensor", *history.versions):
            table.add_column(column, overflow="fold")
        for rule, sensors in history.regime_rmse.items():
            shares = history.regime_share[rule]
            share = next((f" ({100 * s:.0f} %)" for s in shares if s == s), "")
            number = history.regime_number.get(rule, "–")  # the run's, as the report numbers it
            for i, (sensor, values) in enumerate(sensors.items()):
                table.add_row(number if i == 0 else "", rule + share if i == 0 else "", local_name(sensor),
                              *[quantity_text(v, history.units.get(sensor, "")) for v in values])
            table.add_section()
        console.print(table)
    if plot is not None:
        from service.report.plots import plot_error_history

        console.print(f"plot: {plot_error_history(plot, history)}")


@app.command("report")
@reports_errors
def report_command(
    run: Annotated[str, typer.Argument(help="Run id (printed by calibrate and diagnose; \"run\" in diagnose --json).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="HTML file to write.")] = Path("report.html"),
    data: Annotated[Path | None, typer.Option(help="The run's measurement CSV (default: the file name the run "
                                                   "recorded, in the current folder).")] = None,
    store: StoreOption = DEFAULT_STORE,
) -> None:
    """One self-contained HTML page for RUN: measured vs model per sensor, where it fails on the flow
    topology, the operating regimes, the missing effects with their evidence, the error across versions."""
    from service.report.page import report_html
    from service.report.run_series import data_file_locator

    if data is not None and not data.is_file():
        raise NotFoundError(f"{data}: no such file")
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
    except NotFoundError as exc:  # the store searched, named: a run is often in another --store
        raise NotFoundError(f"{exc} at {store} (--store: the folder the run was written to)") from None
    output.write_text(page, encoding="utf-8")
    console.print(f"wrote {output}")
    for problem in dict.fromkeys(missing):
        console.print(f"[yellow]warning:[/] {problem}: the page has no measured-vs-model plots", markup=True)


@app.command("serve")
@reports_errors
def serve_command(
    store: Annotated[Path | None, typer.Option("--store", help="Embedded store folder (default ./graphtwin-data, "
                                                               "or GRAPHTWIN_STORE_DIR).")] = None,
    sparql_endpoint: Annotated[str | None, typer.Option("--sparql-endpoint", help="Use this SPARQL 1.1 endpoint "
                                                        "(Oxigraph server layout) instead of an embedded store.")] = None,
    data_dir: Annotated[Path | None, typer.Option("--data-dir", help="Job records and measurement uploads "
                                                  "(default ./graphtwin-service, or GRAPHTWIN_DATA_DIR).")] = None,
    executor: Annotated[str | None, typer.Option(
        "--executor", help="Where job work runs: threads, processes or dask://HOST:PORT "
                           "(default: GRAPHTWIN_EXECUTOR, else processes).")] = None,
    host: Annotated[str, typer.Option(help="Interface to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port.")] = 8000,
) -> None:
    """Run the HTTP service (OpenAPI at /docs). Writes need the bearer token in GRAPHTWIN_TOKEN; the
    other settings come from GRAPHTWIN_* variables (docs/http.md, Settings)."""
    import uvicorn

    from service.http.app import create_app
    from service.settings import load_settings

    if store is not None and sparql_endpoint is not None:
        raise fail("give --store or --sparql-endpoint, not both")
    overrides = {"store_dir": store, "sparql_endpoint": sparql_endpoint, "data_dir": data_dir, "executor": executor}
    options = {"store_dir": "--store", "sparql_endpoint": "--sparql-endpoint", "data_dir": "--data-dir",
               "executor": "--executor"}
    try:
        settings = load_settings(options, **{k: v for k, v in overrides.items() if v is not None})
    except InputError as exc:
        raise fail(exc) from None
    if settings.store_dir is None and settings.sparql_endpoint is None:
        settings = settings.model_copy(update={"store_dir": DEFAULT_STORE})
    if settings.token is None:
        error_console.print("[yellow]GRAPHTWIN_TOKEN is not set: every write will be refused.[/yellow]")
    uvicorn.run(create_app(settings), host=host, port=port)
