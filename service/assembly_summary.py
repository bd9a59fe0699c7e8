"""Readable and JSON summaries of an assembled model (what ``graphtwin assemble`` prints)."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.table import Table

from .assembled_model import AssembledModel, ParameterRef

__all__ = ["assembly_to_dict", "print_assembly"]


def _parameter_entry(ref: ParameterRef) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "component": ref.component, "name": ref.name, "unit": ref.spec.unit,
        "lower": ref.spec.lower, "upper": ref.spec.upper,
    }
    if ref.value is not None:
        entry["value"] = ref.value
    else:
        entry["default"] = ref.spec.default
    return entry


def assembly_to_dict(model: AssembledModel) -> dict[str, Any]:
    """JSON-ready: keys ``components``, ``connections``, ``boundary_inputs``, ``targets``,
    ``parameters`` (``mapped`` / ``estimated``) and ``notes``; every entry names IRIs."""
    return {
        "components": [
            {"iri": iri, "signature": c.signature.iri, "signature_id": c.signature.id, "represents": list(c.modeled_nodes)}
            for iri, c in model.components.items()
        ],
        "connections": [
            {"from": c.source, "from_port": c.source_port, "to": c.target, "to_port": c.target_port}
            for c in model.connections
        ],
        "boundary_inputs": [_device_entry(model, iri) for iri in model.boundary_inputs],
        "targets": [_device_entry(model, iri) for iri in model.targets],
        "parameters": {
            "mapped": [_parameter_entry(p) for p in model.mapped_parameters],
            "estimated": [_parameter_entry(p) for p in model.estimated_parameters],
        },
        "notes": list(model.notes),
    }


def _device_entry(model: AssembledModel, iri: str) -> dict[str, Any]:
    link = model.measurement(iri)
    return {"component": iri, "node": link.node, "series_id": link.series_id, "unit": link.unit}


def print_assembly(model: AssembledModel, console: Console | None = None) -> None:
    console = console or Console()
    components = Table(title="Components", show_lines=False)
    for column in ("signature", "represents"):
        components.add_column(column)
    for c in model.components.values():
        components.add_row(c.signature.id, "\n".join(c.modeled_nodes))
    console.print(components)

    devices = Table(title="Measured devices")
    for column in ("role", "device", "column", "unit"):
        devices.add_column(column)
    for role, iris in (("boundary input", model.boundary_inputs), ("target", model.targets)):
        for iri in iris:
            link = model.measurement(iri)
            devices.add_row(role, link.node, link.series_id or "-", link.unit or "-")
    console.print(devices)

    parameters = Table(title="Parameters")
    for column in ("component", "parameter", "unit", "value / bounds"):
        parameters.add_column(column)
    for ref in model.mapped_parameters:
        parameters.add_row(model.components[ref.component].node, ref.name, ref.spec.unit, f"mapped {ref.value:g}")
    for ref in model.estimated_parameters:
        parameters.add_row(model.components[ref.component].node, ref.name, ref.spec.unit,
                           f"estimate in [{ref.spec.lower:g}, {ref.spec.upper:g}]")
    console.print(parameters)
    console.print(f"{len(model.connections)} connections, {len(model.boundary_inputs)} boundary inputs, "
                  f"{len(model.targets)} targets, {len(model.mapped_parameters)} mapped and "
                  f"{len(model.estimated_parameters)} estimated parameters")
    for note in model.notes:
        console.print(f"[yellow]note:[/yellow] {note}")
