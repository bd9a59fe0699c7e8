"""Measurement CSVs written in the data contract's shape (``docs/data.md``): synthetic data, and
measured series beside their simulation (``graphtwin simulate -o``), which read back as they were."""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from service.data.measurements import MeasuredData
from service.graph.units import convert

__all__ = ["write_csv", "write_comparison_csv"]


def write_csv(path: Path, timestamps: np.ndarray, columns: Mapping[str, np.ndarray], *, decimals: int = 4) -> None:
    """Write ``columns`` beside an ISO time column (``time``); NaN as an empty cell."""
    with Path(path).open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", *columns])
        arrays = list(columns.values())
        for i, stamp in enumerate(timestamps):
            cells = [str(np.datetime64(stamp, "s")).replace("T", " ")]
            cells += ["" if not np.isfinite(a[i]) else f"{a[i]:.{decimals}f}" for a in arrays]
            writer.writerow(cells)


def write_comparison_csv(path: Path, data: MeasuredData, simulated: Mapping[str, np.ndarray], *, decimals: int = 4) -> None:
    """Write every measured series beside its simulation: for each node of ``data``, its column
    (the file's header, the file's unit) and, when ``simulated`` has the node, ``<header> (simulated)``
    in the same unit. The result reads back with :func:`~service.data.measurements.read_measurements` and the same model (the
    simulated columns are then unclaimed columns).

    :param simulated: node IRI → ``ndarray[n_steps]`` in the port unit ``data.units[node]``.
    :raises ValueError: a simulated node without a series in ``data``, or a series of another length.
    """
    unknown = sorted(set(simulated) - set(data.series))
    if unknown:
        raise ValueError(f"simulated series for node(s) the data {data.source} does not hold: {', '.join(unknown)}")
    columns: dict[str, np.ndarray] = {}
    for node, measured in data.series.items():
        header = data.columns.get(node, node)
        unit = data.source_units.get(node, data.units[node])
        columns[header] = convert(measured, data.units[node], unit, where=f"column {header!r}")
        if node in simulated:
            values = np.asarray(simulated[node], dtype=float)
            if values.shape != (data.n_steps,):
                raise ValueError(f"simulated series for {node} has shape {values.shape}, the data {data.n_steps} steps")
            columns[f"{header} (simulated)"] = convert(values, data.units[node], unit, where=f"column {header!r}")
    write_csv(path, data.timestamps, columns, decimals=decimals)
