"""A measurement file's cells: the bytes decoded (UTF-8, else Windows-1252 with a warning), the
delimiter told (``;`` for a European export, which may write decimal commas, else ``,``), the header
row apart. What :func:`~service.data.measurements.read_measurements` checks and
:func:`~service.data.block_means.write_block_means` averages.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

from service.errors import MeasurementError

__all__ = ["CsvTable", "read_csv_table"]


def _decoded(raw: bytes, source: str, warnings: list[str]) -> str:
    """The file's text: UTF-8 (a byte-order mark dropped), else Windows-1252 — what a BMS export
    with a ``°`` in its headers often is — with a warning.

    :raises MeasurementError: neither, naming the first offending byte's line and offset.
    """
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as utf8:
        where = "line %d" % (raw.count(b"\n", 0, utf8.start) + 1)
        try:
            text = raw.decode("cp1252")
        except UnicodeDecodeError:
            raise MeasurementError(source, [
                f"{where}: byte 0x{raw[utf8.start]:02x} at offset {utf8.start} is neither UTF-8 nor "
                "Windows-1252 text: is this a CSV file?"]) from None
        warnings.append(f"not UTF-8 ({where}: byte 0x{raw[utf8.start]:02x}): read as Windows-1252")
        return text


@dataclass(frozen=True)
class CsvTable:
    """A measurement file's cells as written: its header row, the rows after it, and its delimiter
    (``;``, a European export, which may write decimal commas; else ``,``)."""

    header: list[str]
    rows: list[list[str]]
    delimiter: str

    def number(self, cell: str) -> float:
        """A cell's number, a decimal comma read in a ``;`` file. :raises ValueError: none."""
        return float(cell.replace(",", ".") if self.delimiter == ";" else cell)


def read_csv_table(path: Path, source: str, warnings: list[str]) -> CsvTable:
    """The cells of the CSV at ``path`` (decoded by :func:`_decoded`, which may add to ``warnings``);
    ``source`` names it in messages.

    :raises MeasurementError: no such file, unreadable, not text, or empty.
    """
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise MeasurementError(source, ["no such file"]) from None
    except OSError as exc:
        raise MeasurementError(source, [f"cannot be read: {exc.strerror or exc}"]) from None
    text = _decoded(raw, source, warnings)
    first_line = text.split("\n", 1)[0]
    delimiter = ";" if ";" in first_line and "," not in first_line else ","
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    try:
        header = next(reader)
    except StopIteration:
        raise MeasurementError(source, ["the file is empty"]) from None
    return CsvTable(header, list(reader), delimiter)
