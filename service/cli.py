"""The ``graphtwin`` command line: the same jobs as the HTTP service, run locally.

Every command takes ``--store DIR`` (the embedded Oxigraph store on disk, default
``./graphtwin-data``) or ``--memory`` (a throw-away in-memory store).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.syntax import Syntax

from .assembly import AssemblyError, assemble
from .assembly_summary import assembly_to_dict, print_assembly
from .assembly_triples import assembly_triples
from .namespaces import graph_iri
from .resources import signatures_dir
from .signature import SignatureError, load_signature_library
from .sparql_compiler import compile_signature
from .store import GraphStore, ModelLoadError

__all__ = ["app"]

app = typer.Typer(no_args_is_help=True, add_completion=False, help=__doc__)
signature_app = typer.Typer(no_args_is_help=True, help="Inspect the signature library.")
app.add_typer(signature_app, name="signature")

console = Console()
error_console = Console(stderr=True)

StoreOption = Annotated[Path, typer.Option("--store", help="Embedded store folder (created if missing).")]
MemoryOption = Annotated[bool, typer.Option("--memory", help="Use a throw-away in-memory store.")]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")]


def open_store(store: Path, memory: bool) -> GraphStore:
    return GraphStore(None if memory else store)


def model_name_for(path: Path, name: str | None) -> str:
    """The model's name in the store: ``--name``, else the file stem (the folder for ``model.ttl``)."""
    if name:
        return name
    return path.parent.name if path.stem == "model" else path.stem


def fail(message: str) -> typer.Exit:
    error_console.print(f"[bold red]error:[/bold red] {message}")
    return typer.Exit(code=2)


@app.command("assemble")
def assemble_command(
    model: Annotated[Path, typer.Argument(help="Building model (Turtle, N-Triples, RDF/XML, JSON-LD).")],
    name: Annotated[str | None, typer.Option(help="Model name in the store (default: from the file name).")] = None,
    max_complexity: Annotated[int | None, typer.Option(help="Ignore signatures above this complexity.")] = None,
    as_json: JsonOption = False,
    store: StoreOption = Path("graphtwin-data"),
    memory: MemoryOption = False,
) -> None:
    """Load MODEL into the store, assemble its simulation model and write it back as triples."""
    graph_store = open_store(store, memory)
    model_name = model_name_for(model, name)
    try:
        graph_store.load_model(model_name, model)
        assembled = assemble(graph_store, model_name, max_complexity=max_complexity)
    except (ModelLoadError, AssemblyError, SignatureError, FileNotFoundError) as exc:
        raise fail(str(exc)) from None
    graph_store.write_graph(graph_iri("assembly", model_name), assembly_triples(assembled, model_name))
    if as_json:
        console.print_json(json.dumps(assembly_to_dict(assembled)))
    else:
        print_assembly(assembled, console)


@signature_app.command("list")
def signature_list() -> None:
    """List the signatures of the library."""
    for signature in load_signature_library(signatures_dir()).values():
        console.print(f"{signature.id:24s} {signature.kind:9s} {signature.label}")


@signature_app.command("explain")
def signature_explain(name: Annotated[str, typer.Argument(help="Signature id, e.g. Fan.")]) -> None:
    """Print the SPARQL query a signature compiles to."""
    library = load_signature_library(signatures_dir())
    if name not in library:
        raise fail(f"no signature {name!r}; known: {', '.join(sorted(library))}")
    console.print(Syntax(compile_signature(library[name]).text, "sparql", word_wrap=True))
