"""What every command shares: the consoles, the options, the store it opens, the model file it loads,
and the one place where graphtwin's errors become a one-line message and exit code 2."""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, ParamSpec

import typer
from rich.console import Console
from rich.text import Text

from service.components.library import SignatureLibrary
from service.errors import GraphtwinError, IncompleteModelError, InputError
from service.graph.store import GraphStore
from service.graph.vocabulary import with_term_locations
from service.matching.library_triples import ensure_signature_library

__all__ = [
    "app", "signature_app", "example_app", "data_app", "console", "error_console", "fail", "error_text",
    "reports_errors", "open_store", "model_name_for", "loaded_model_file", "USER_ERROR_EXIT_CODE",
]

app = typer.Typer(no_args_is_help=True, add_completion=False, help=(
    "The graphtwin command line: the same work as the HTTP service, run locally.\n\n"
    "Every command that touches the store takes --store DIR (the embedded Oxigraph store on disk, default "
    "./graphtwin-data); those that load a model file (assemble, simulate, calibrate, diagnose, compare) "
    "take --memory instead for a throw-away in-memory store (brick-report too), and those that read what runs stored (history, "
    "report, query) need the store the runs were written to. A model argument is a file (Turtle, "
    "N-Triples, RDF/XML, JSON-LD), loaded under --name (default: the file name); add-effect only writes a "
    "new file."))
signature_app = typer.Typer(no_args_is_help=True, help="Inspect the signature library.")
example_app = typer.Typer(no_args_is_help=True, help="Example models and synthetic data.")
data_app = typer.Typer(no_args_is_help=True, help="Prepare measurement files.")
app.add_typer(signature_app, name="signature")
app.add_typer(example_app, name="example")
app.add_typer(data_app, name="data")

console = Console()
error_console = Console(stderr=True)
#: Columns of the tables written to a file or a pipe (no terminal to measure; COLUMNS still decides).
PIPED_WIDTH = 160


@app.callback()
def _width_of_the_output() -> None:
    # written to a file or a pipe, rich would fold every table at 80 columns: a log is read wider
    for each in (console, error_console):
        each.width = None if each.is_terminal or "COLUMNS" in os.environ else PIPED_WIDTH

#: The exit code of a command refused for its input (a user's error, not a defect).
USER_ERROR_EXIT_CODE = 2

#: The embedded store's folder when a command is given no --store.
DEFAULT_STORE = Path("graphtwin-data")
StoreOption = Annotated[Path, typer.Option("--store", help="Embedded store folder (created if missing).")]
MemoryOption = Annotated[bool, typer.Option("--memory", help="Use a throw-away in-memory store.")]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")]
NameOption = Annotated[str | None, typer.Option("--name", help="Model name in the store (default: from the file name).")]
SeedOption = Annotated[int, typer.Option("--seed", help="Random seed (runs are reproducible).")]
OnlyWhenOption = Annotated[list[str] | None, typer.Option(
    "--only-when", help="Fit and compare only at steps where COLUMN OP NUMBER [UNIT] holds, in the column's unit "
                        "(e.g. 'SF Spd Cmd (%) > 5', or a regime rule as printed: 'supply fan speed command ≤ 11 %'); "
                        "repeat for several (all must hold).")]
ModelFileArgument = Annotated[Path, typer.Argument(help="Building model file.")]
MeasurementsArgument = Annotated[Path, typer.Argument(help="Measurement CSV (docs/data.md: the data contract).")]
TrainWindowOption = Annotated[str, typer.Option(help="Training window START/END (ISO; either side may be empty).")]
TestWindowOption = Annotated[str | None, typer.Option(help="Test window START/END.")]
StartFromOption = Annotated[str | None, typer.Option(help=(
    "A model in the store whose latest calibrated parameters start the fit (the version before `add-effect`, "
    "or the model itself: a warm start on new data); the others, an added effect's, start at their defaults."))]


def error_text(exc: BaseException) -> str:
    """What an error says, for a person: a missing file as ``PATH: No such file or directory``."""
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror}"
    return str(exc)


def fail(problem: str | BaseException) -> typer.Exit:
    """Print ``problem`` (a message, or an exception as :func:`error_text` reads it) as an error, as
    it is (no markup read in it, no line breaks added) → exit code 2."""
    message = problem if isinstance(problem, str) else error_text(problem)
    error_console.print(Text.assemble(("error:", "bold red"), " ", message), soft_wrap=True)
    return typer.Exit(code=USER_ERROR_EXIT_CODE)


P = ParamSpec("P")


def reports_errors(command: Callable[P, None]) -> Callable[P, None]:
    """A command whose user errors — graphtwin's (:class:`~service.errors.GraphtwinError`) and a file
    that cannot be read — end it with their message and exit code 2; Ctrl-C with one line and exit
    code 130 (also where it lands inside compiled code, which raises it as a SystemError); anything
    else is a defect and shows its traceback."""

    @functools.wraps(command)
    def run(*args: P.args, **kwargs: P.kwargs) -> None:
        try:
            command(*args, **kwargs)
        except (GraphtwinError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
            raise fail(exc) from None
        except (KeyboardInterrupt, SystemError) as exc:
            if not _interrupted(exc):
                raise
            error_console.print("interrupted (Ctrl-C): results the command had not written yet are not in the store",
                                markup=False)
            raise typer.Exit(130) from None

    return run


def _interrupted(exc: BaseException | None) -> bool:
    """Whether ``exc`` is Ctrl-C, or an error raised while handling it (numba's compiled loops turn a
    KeyboardInterrupt into "SystemError: … returned a result with an exception set")."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def open_store(store: Path, memory: bool, *, reading: bool = False, start_from: str | None = None) -> GraphStore:
    """The embedded store with the ontology subsets and the signature library loaded. ``reading``:
    the command only reads results, so a folder that holds no store is an error (a mistyped
    ``--store`` would otherwise be a new, empty store). ``start_from``: a model whose stored
    calibration the command starts from, which a throw-away store cannot hold.

    :raises StoreInUseError: another process holds the store.
    :raises InputError: no store at ``store`` (``reading``), or ``start_from`` with ``memory``.
    """
    if reading and not memory and not store.is_dir():
        raise InputError(f"no store at {store}: give --store the folder a calibration or diagnosis wrote")
    if memory and start_from:
        raise InputError(f"--start-from {start_from} reads that model's calibration from the store, and --memory "
                         f"starts an empty one: drop --memory (the store is {store}, or give --store)")
    graph_store = GraphStore.embedded(None if memory else store)
    graph_store.ensure_ontologies()
    ensure_signature_library(graph_store, SignatureLibrary.load())
    return graph_store


def model_name_for(path: Path, name: str | None) -> str:
    """The model's name in the store: ``--name``, else the file stem (the folder named with it for
    ``…/NAME/model.ttl``; ``model`` for a ``model.ttl`` in the current folder)."""
    if name:
        return name
    return path.parent.name if path.stem == "model" and path.parent.name else path.stem


@contextmanager
def loaded_model_file(store: GraphStore, model: Path, name: str | None) -> Iterator[str]:
    """The model file ``model`` loaded under ``--name`` (or the name :func:`model_name_for` gives),
    for a command's work: its name. Where that work fails (measurements that do not fit the model,
    a model nothing in the library matches), the store's model of that name is put back as it was.

    :raises InputError: the file's name is no model name and ``--name`` was not given.
    """
    model_name = model_name_for(model, name)
    if name is None:
        try:
            GraphStore.check_name(model_name)
        except InputError as exc:
            raise InputError(f"{exc}; the name comes from {model}: give one with --name") from None
    load = store.load_model(model_name, model, keep_previous=True)
    try:
        yield model_name
    except IncompleteModelError as exc:  # a misspelling among its causes is said with its line in the file
        store.undo_load(model_name, load)
        text = model.read_text(encoding="utf-8", errors="replace")
        raise IncompleteModelError(with_term_locations(exc.problems, text, model.name), headline=exc.headline,
                                   notes=with_term_locations(exc.notes, text, model.name)) from None
    except BaseException:
        store.undo_load(model_name, load)
        raise
