"""Readable and JSON summaries of an assembled model (what ``graphtwin assemble`` prints)."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.table import Table

from service.graph.namespaces import compact_iri, distinct_local_names, namespace_of
from service.graph.units import unit_label
from service.model.assembled_model import AssembledModel, ParameterRef
from service.model.wiring import without_model

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


def _value_source(model: AssembledModel, ref: ParameterRef) -> str:
    """"mapped" for a value the graph states, "fixed" for one the component's model sets from what is
    measured (:meth:`~service.components.component.ComponentModel.parameters_fixed_by_measurement`:
    a fan's impeller heat is 0 where no meter measures its power)."""
    return "mapped" if ref.name in model.components[ref.component].mapped_parameters else "fixed"


def _device_entry(model: AssembledModel, iri: str) -> dict[str, Any]:
    link = model.measurement(iri)
    return {"component": iri, "node": link.node, "series_id": link.series_id, "unit": link.unit}


def print_assembly(model: AssembledModel, console: Console | None = None) -> None:
    """The assembly as tables for a terminal: building nodes by their local names (hashed where two
    share one; the namespaces they come from said once), units by their labels. ``--json`` has the IRIs."""
    console = console or Console()
    nodes = [n for c in model.components.values() for n in c.modeled_nodes]
    name = distinct_local_names(nodes)
    namespaces = sorted({namespace_of(iri) for iri in nodes})
    components = Table(title="Components", caption=f"nodes in {', '.join(namespaces)}", show_lines=False)
    for column in ("signature", "represents"):
        components.add_column(column, overflow="fold")
    for c in model.components.values():
        components.add_row(c.signature.id, "\n".join(name[n] for n in c.modeled_nodes))
    console.print(components)

    devices = Table(title="Measured devices")
    for column in ("role", "device", "column", "unit"):
        devices.add_column(column, overflow="fold")
    for role, iris in (("boundary input", model.boundary_inputs), ("target", model.targets)):
        for iri in iris:
            link = model.measurement(iri)
            devices.add_row(role, name.get(link.node, link.node), link.series_id or "-",
                            unit_label(link.unit) if link.unit else "-")
    console.print(devices)

    parameters = Table(title="Parameters")
    for column in ("component", "parameter", "unit", "value / bounds"):
        parameters.add_column(column, overflow="fold")
    def states_none(ref) -> str:
        stating = model.components[ref.component].signature.stating_property(ref.name)
        return f"; the graph states none ({compact_iri(stating)})" if stating else ""

    for ref in model.mapped_parameters:
        source = _value_source(model, ref)
        parameters.add_row(without_model(ref.component), ref.name, ref.spec.unit,
                           f"{source} {ref.value:g}" + (states_none(ref) if source == "fixed" else ""))
    for ref in model.estimated_parameters:
        parameters.add_row(without_model(ref.component), ref.name, ref.spec.unit,
                           f"estimate in [{ref.spec.lower:g}, {ref.spec.upper:g}]" + states_none(ref))
    console.print(parameters)
    fixed = sum(_value_source(model, ref) == "fixed" for ref in model.mapped_parameters)
    console.print(f"{len(model.connections)} connections, {len(model.boundary_inputs)} boundary inputs, "
                  f"{len(model.targets)} targets, {len(model.mapped_parameters) - fixed} mapped, "
                  f"{fixed} fixed by what is or is not measured and {len(model.estimated_parameters)} estimated parameters")
    for note in model.notes:
        console.print(f"[yellow]note:[/yellow] {note}")
