"""Block means of a measurement file: a BMS log at 1 minute written as means over clock-aligned
blocks (15 minutes for the FLEXLAB days, ``docs/real-days.md``), so that a model whose dynamics are
slower than the log's step is compared with what it can predict.

A block starts at a multiple of its length from midnight and is stamped with its start; it is written
only where the log covers it whole (as many rows as its length holds at the log's usual step), so
every mean spans the same time. Cells that hold no number (spreadsheet errors, empty cells) are left
out of a column's mean; a block without a number in a column leaves that cell empty.
"""

from __future__ import annotations

import csv
from collections.abc import Collection
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from service.data.csv_table import read_csv_table
from service.data.measurements import parse_timestamp
from service.errors import InputError, MeasurementError

__all__ = ["write_block_means"]


def write_block_means(source: Path, target: Path, minutes: int, days: Collection[str] | None = None) -> int:
    """Write the rows of the CSV ``source`` (a time column, then series) as ``minutes``-long block
    means to ``target``, the header unchanged; ``days``: the ISO dates to keep (all when None).
    Returns the number of blocks written.

    :raises MeasurementError: the file cannot be read (:func:`~service.data.csv_table.read_csv_table`),
        a time stamp does not parse (its line), or a day asked for has no rows.
    :raises InputError: ``minutes`` is not a positive whole number of the log's steps.
    """
    table = read_csv_table(source, str(source), [])
    header, rows = table.header, table.rows

    def number(cell: str) -> float:
        """The cell's finite number, else NaN (a spreadsheet error, an empty cell)."""
        try:
            value = table.number(cell)
        except ValueError:
            return float("nan")
        return value if np.isfinite(value) else float("nan")

    stamps: list[datetime] = []
    for line, row in enumerate(rows, start=2):
        try:
            stamps.append(parse_timestamp(row[0]))
        except (InputError, IndexError) as exc:
            raise MeasurementError(str(source), [f"line {line}: {exc}"]) from None
    absent = sorted(set(days or ()) - {t.date().isoformat() for t in stamps})
    if absent:
        raise MeasurementError(str(source), [f"no rows on {', '.join(absent)} (the log runs from "
                                             f"{min(stamps, default='-')} to {max(stamps, default='-')})"])
    kept = [(t, row) for t, row in zip(stamps, rows) if days is None or t.date().isoformat() in days]
    if len(kept) < 2:
        raise MeasurementError(str(source), ["fewer than two rows"])
    step_s = float(np.median(np.diff([t.timestamp() for t, _ in kept])))
    rows_per_block = minutes * 60.0 / step_s
    if minutes <= 0 or step_s <= 0 or abs(rows_per_block - round(rows_per_block)) > 1e-9:
        raise InputError(f"blocks of {minutes} min: give a positive whole multiple of the log's step ({step_s:g} s)")
    blocks: dict[datetime, list[list[str]]] = {}
    for stamp, row in kept:
        midnight = stamp.replace(hour=0, minute=0, second=0, microsecond=0)
        start = midnight + timedelta(minutes=minutes * ((stamp - midnight) // timedelta(minutes=minutes)))
        blocks.setdefault(start, []).append(row)
    out = [header]
    for start, members in sorted(blocks.items()):
        if len(members) != round(rows_per_block):
            continue
        values = np.array([[number(row[c]) if c < len(row) else np.nan for c in range(1, len(header))]
                           for row in members])
        columns = (column[np.isfinite(column)] for column in values.T)
        out.append([start.isoformat(sep=" ")] + [repr(float(np.mean(c))) if c.size else "" for c in columns])
    with target.open("w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows(out)
    return len(out) - 1
