"""The plant's trend as the measurement CSV users feed graphtwin (first column the ISO time stamp,
then one column per sensor's ``gt:timeSeriesId``), with the truth kept apart."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .faults import FAULTS, Fault, FaultTruth
from .plant import PlantRun, PlantSettings, simulate_plant

__all__ = ["write_plant_csv", "write_run_csv"]

#: Decimals written per column (the readings are quantised already; this keeps the file exact).
_DECIMALS = {"supply_air_flow": 3, "supply_fan_power": 0, "valve_position": 3}


def write_run_csv(run: PlantRun, path: Path | str) -> None:
    """Write ``run``'s readings to ``path``."""
    columns = list(run.readings)
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["timestamp", *columns])
        stamps = np.datetime_as_string(run.timestamps, unit="s")
        for i, stamp in enumerate(stamps):
            writer.writerow([stamp.replace("T", " "),
                             *(f"{run.readings[c][i]:.{_DECIMALS.get(c, 2)}f}" for c in columns)])


def write_plant_csv(path: Path | str, *, fault: str | None = None, size: float | None = None,
                    fault_start: str | None = None, seed: int = 0, days: float = 7.0,
                    start: str = "2026-01-15T00:00", space_column: bool = False,
                    settings: PlantSettings | None = None) -> FaultTruth:
    """Simulate the plant, write its CSV to ``path`` and return what was injected. ``size``: the
    fault's size (default: its ``clear`` size); ``fault_start``: ISO date-time (default: ``start``)."""
    injected = None
    if fault is not None:
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {', '.join(FAULTS)}")
        offset_s = 0.0
        if fault_start is not None:
            offset_s = float((np.datetime64(fault_start, "s") - np.datetime64(start, "s")).astype(float))
        injected = Fault(name=fault, size=FAULTS[fault].clear if size is None else size, start_s=offset_s)
    run = simulate_plant(days=days, start=start, seed=seed, fault=injected, settings=settings,
                         space_column=space_column)
    write_run_csv(run, path)
    return run.truth
