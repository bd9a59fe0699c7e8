"""The measured-data contract: a CSV of time stamps and sensor columns, matched to graph nodes.

The first column is the time stamp (ISO 8601, an offset converted to UTC; BMS ``m/d/yyyy h:mm``;
European ``d.m.yyyy h:mm``), every other a series matched to a measuring device by its IRI, local
name or ``gt:timeSeriesId`` and converted from the device's QUDT unit to the model port's. Every
problem (cells, stamps, row lengths, missing or doubled columns, percent declared as a fraction) is
reported at once in one :class:`MeasurementError` naming column and line; unclaimed columns and
frozen points are warnings. The step is the median spacing (an irregular file is resampled); gaps
up to ``max_gap_steps`` are interpolated (held at the last value for schedules, a zero-order hold;
resampled to the nearer row), longer ones stay NaN. The full contract: ``docs/data.md``.
"""

from __future__ import annotations

import difflib
import re
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from service.data.csv_table import read_csv_table
from service.errors import InputError, MeasurementError
from service.graph.namespaces import local_name
from service.graph.units import KNOWN_UNITS, UnitError, convert, unit_label

__all__ = ["MeasurementError", "MeasuredData", "SeriesSpec", "read_measurements", "parse_timestamp", "frozen_spans"]

_MISSING = {"", "nan", "na", "n/a", "null", "none", "-"}
_BMS_FORMATS = ("%m/%d/%Y %H:%M", "%m/%d/%y %H:%M", "%m/%d/%Y %H:%M:%S", "%m/%d/%y %H:%M:%S",
                "%d.%m.%Y %H:%M", "%d.%m.%Y %H:%M:%S")


@dataclass(frozen=True)
class SeriesSpec:
    """What the model needs from a column: the device ``node`` IRI, the names a column may carry
    (``series_id``), the QUDT ``unit`` the values are in, the ``port_unit`` the model wants, and
    whether the model cannot run without it (``required``); ``holds_values``: it may hold one value
    for days (a schedule, a command), so no frozen-point warning; ``steps``: it steps between samples
    (a schedule), so gaps and resampling hold a value rather than interpolate."""

    node: str
    series_id: str | None
    unit: str | None
    port_unit: str
    required: bool = True
    holds_values: bool = False
    steps: bool = False

    def names(self) -> set[str]:
        local = local_name(self.node)
        return {n.strip() for n in (self.node, local, self.series_id) if n and n.strip()}


@dataclass(frozen=True)
class MeasuredData:
    """Regular series on one time grid: ``series[node]`` (``ndarray[n_steps]``) in the port unit
    ``units[node]``, read from the CSV column ``columns[node]`` recorded in the QUDT unit
    ``source_units[node]``; NaN where not measured (gaps longer than the limit), and :attr:`valid`
    masks the steps where every series is measured."""

    timestamps: np.ndarray  # datetime64[s], UTC or naive local as in the file
    step_s: float
    series: dict[str, np.ndarray]
    units: dict[str, str]
    source: str = "<data>"
    columns: dict[str, str] = field(default_factory=dict)  # node → CSV column
    warnings: tuple[str, ...] = ()
    source_units: dict[str, str] = field(default_factory=dict)  # node → the QUDT unit of its column
    utc: bool = False  # the file gave its stamps with a UTC offset: ``timestamps`` are UTC
    #: header → the numbers of a column no device claims (a fan status), in the file's own unit, on the
    #: same grid (NaN where a cell is empty or no number): what an operating filter may read
    other_columns: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return int(self.timestamps.size)

    @property
    def valid(self) -> np.ndarray:
        """``ndarray[n_steps]`` of bool: steps where every series is measured (no long gap)."""
        mask = np.ones(self.n_steps, dtype=bool)
        for values in self.series.values():
            mask &= np.isfinite(values)
        return mask

    def window(self, start: datetime | str | None, end: datetime | str | None, label: str = "window") -> slice:
        """Index slice of the steps with ``start ≤ t ≤ end`` (None: the data's first / last); ``label``
        names the window in errors (``"training window"``).

        :raises InputError: a window outside the data or empty, naming the data's range; a window
            reaching more than one step beyond the data's first or last time stamp (``2026-01-14``
            as the end of data that stop at 23:50 the day before is fine; a week of data asked of a
            day is not cut silently).
        """
        first, last = self.timestamps[0], self.timestamps[-1]
        lo = first if start is None else self._bound(start, f"{label}'s start")
        hi = last if end is None else self._bound(end, f"{label}'s end")
        window = f"{label} {self.shown(lo)} – {self.shown(hi)}"
        data = f"the data {self.source} ({self.shown(first)} – {self.shown(last)})"
        if lo > last or hi < first:  # before the order: an open end is the data's, not the user's
            raise InputError(f"{window} lies outside {data}")
        if hi < lo:
            raise InputError(f"{window}: the end is before the start")
        step = np.timedelta64(int(round(self.step_s)), "s")
        if lo < first - step or hi > last + step:
            side = "starts before" if lo < first - step else "ends after"
            raise InputError(f"{window} {side} {data}: give a window inside the data")
        i = int(np.searchsorted(self.timestamps, lo, side="left"))
        j = int(np.searchsorted(self.timestamps, hi, side="right"))
        if j - i < 2:
            raise InputError(f"{window} holds fewer than 2 steps of {self.source}")
        return slice(i, j)

    def _bound(self, value: datetime | str, which: str) -> np.datetime64:
        """A window bound on the data's clock: with a UTC offset where the file gives its stamps with
        one (they are read as UTC), without one where the file's are local (an offset would shift
        the window by it, silently).

        :raises InputError: a bound on the other clock."""
        text = value.isoformat() if isinstance(value, datetime) else str(value)
        stamp, with_offset = _parsed_timestamp(text)
        if with_offset != self.utc:
            stamps = "with a UTC offset (read as UTC)" if self.utc else "without a UTC offset (local time)"
            wanted = "with an offset too (…T06:00-07:00, or …T13:00Z)" if self.utc else "without an offset"
            raise InputError(f"the {which} {text!r}: the data {self.source} give their time stamps {stamps}; "
                             f"give it {wanted}")
        return np.datetime64(stamp, "s")

    def shown(self, stamp: np.datetime64) -> str:
        """A time stamp of the data as text (:func:`_stamp_text`)."""
        return _stamp_text(stamp, self.utc)

    def select(self, start: datetime | str | None, end: datetime | str | None) -> MeasuredData:
        """The data with ``start ≤ t ≤ end`` (errors as :meth:`window`)."""
        window = self.window(start, end)
        return replace(self, timestamps=self.timestamps[window], series={k: v[window] for k, v in self.series.items()},
                       other_columns={k: v[window] for k, v in self.other_columns.items()})


def parse_timestamp(text: str) -> datetime:
    """ISO 8601 (an offset is converted to UTC and dropped), the BMS ``m/d/yy h:mm`` or the European
    ``d.m.yyyy h:mm`` format.

    :raises InputError: naming the text.
    """
    return _parsed_timestamp(text)[0]


def _parsed_timestamp(text: str) -> tuple[datetime, bool]:
    """:func:`parse_timestamp`, and whether the text gave a UTC offset."""
    value = text.strip()
    try:
        parsed = datetime.fromisoformat(value.replace("Z", "+00:00"))
    except ValueError:
        for fmt in _BMS_FORMATS:
            try:
                return datetime.strptime(value, fmt), False
            except ValueError:
                continue
        raise InputError(f"time stamp {text!r} is neither ISO 8601 nor m/d/yyyy h:mm nor d.m.yyyy h:mm") from None
    if parsed.tzinfo is not None:
        return parsed.astimezone(timezone.utc).replace(tzinfo=None), True
    return parsed, False


def _stamp_text(stamp: np.datetime64, utc: bool) -> str:
    """A time stamp of the data to the minute (to the second where it has seconds), ``… UTC`` where
    the file's carried offsets."""
    seconds = int(stamp.astype("datetime64[s]").astype(np.int64))
    return np.datetime_as_string(stamp, unit="m" if seconds % 60 == 0 else "s") + (" UTC" if utc else "")


def _duration_text(seconds: float) -> str:
    """``7 d``, ``5 h``, ``20 min``, ``30 s``: a spacing in its largest whole unit."""
    for unit, size in (("d", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:g} s"


def _fill_short_gaps(values: np.ndarray, max_gap: int, *, hold: bool = False) -> tuple[np.ndarray, int]:
    """Interpolate NaN runs of at most ``max_gap`` steps between two measured values (``hold``: keep
    the last value, a zero-order hold for schedules); returns the filled array and the
    number of longer runs left NaN."""
    missing = np.isnan(values)
    if not missing.any() or missing.all():
        return values, int(missing.all())
    out = values.copy()
    index = np.arange(values.size)
    edges = np.diff(np.concatenate([[0], missing.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    long_runs = 0
    known = ~missing
    for start, end in zip(starts, ends):
        if end - start <= max_gap and start > 0 and end < values.size:
            out[start:end] = values[start - 1] if hold else np.interp(index[start:end], index[known], values[known])
        else:
            long_runs += 1
    return out, long_runs


#: A position, command or speed (a fraction in the model) above this after conversion is an error:
#: its column is in percent but declared as a fraction (BMS exports write 0–100).
_FRACTION_MAX = 1.5
#: Years a time stamp may lie in: a stamp outside them is a glitch of the export (9999-12-31, 1900-01-01).
PLAUSIBLE_YEARS = (1970, 2100)
#: The regular grid may hold this many steps a data row, or this many steps in all, whichever is more:
#: beyond both the file is mostly one jump in time (a glitched stamp) that resampling would fill with
#: empty steps, each costing memory in every column.
MAX_GRID_STEPS_PER_ROW, MAX_GRID_STEPS_ANYWAY = 10, 1_000_000


def _check_fraction(values: np.ndarray, where: str, unit: str, problems: list[str], warnings: list[str]) -> None:
    """A series the model reads as a fraction 0–1: an error when it reaches above
    :data:`_FRACTION_MAX` (percent declared as a fraction), a warning when it never exceeds 0.01 but
    is not all zero (a fraction declared as percent)."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        return
    peak, label = float(np.max(np.abs(finite))), unit_label(unit) or "1"
    if peak > _FRACTION_MAX:
        problems.append(f"{where}: reaches {peak:g}, but its unit ({label}) makes it a fraction (0–1): "
                        f"is it in percent? Declare saref:isMeasuredIn unit:PERCENT")
    elif 0 < peak <= 0.01 and unit.endswith("/PERCENT"):
        warnings.append(f"{where}: never above {peak:g} as a fraction (0–1) after conversion from {label}: "
                        f"is it a fraction already? Then declare saref:isMeasuredIn unit:UNITLESS")


def _check_grid_size(source: str, stamps: np.ndarray, step_s: float) -> None:
    """Refuse data whose regular grid would hold more steps than :data:`MAX_GRID_STEPS_PER_ROW` a row
    and :data:`MAX_GRID_STEPS_ANYWAY`, naming the line of its largest jump in time, before the grid
    is built.

    :raises MeasurementError: the data is mostly one jump.
    """
    n_grid = int((stamps[-1] - stamps[0]).astype(np.int64) // max(step_s, 1.0)) + 1
    if n_grid <= max(MAX_GRID_STEPS_PER_ROW * stamps.size, MAX_GRID_STEPS_ANYWAY):
        return
    spacings = np.diff(stamps).astype(np.int64)
    i = int(np.argmax(spacings))
    raise MeasurementError(source, [
        f"line {i + 3}: the time stamps jump from {_stamp_text(stamps[i], False)} to "
        f"{_stamp_text(stamps[i + 1], False)} ({spacings[i] / step_s:.3g} steps of "
        f"{step_s:g} s): on a regular grid the {stamps.size} rows would stand for {n_grid} steps; fix the stamp, "
        "or cut the file at the jump"])


def _near_header(names: set[str], headers: list[str]) -> str | None:
    """The header of ``headers`` most like one of ``names`` (difflib's ratio ≥ 0.8, case ignored; a unit
    in brackets at its end, ``SA-T (°C)``, left out), or None."""
    def like(name: str, header: str) -> float:
        return max(difflib.SequenceMatcher(None, name.lower(), h.lower()).ratio()
                   for h in (header, re.sub(r"\s*[(\[][^)\]]*[)\]]\s*$", "", header)))

    ratio, header = max(((like(n, h), h) for n in names for h in headers), default=(0.0, None))
    return header if ratio >= 0.8 else None


def read_measurements(
    path: Path | str,
    specs: Mapping[str, SeriesSpec],
    *,
    max_gap_steps: int = 5,
    frozen_after_s: float = 12 * 3600.0,
    source_name: str | None = None,
) -> MeasuredData:
    """Read and check a measurement CSV (``docs/data.md``).

    :param specs: node IRI → what the model needs from it.
    :param frozen_after_s: a sensor's value held exactly for this long is reported (:func:`frozen_spans`).
    :param source_name: what messages call the file (default: its path).
    :raises MeasurementError: every problem found, with column and line.
    """
    path = Path(path)
    source = source_name or str(path)
    problems: list[str] = []
    warnings: list[str] = []
    table = read_csv_table(path, source, warnings)
    header, rows, as_number = [h.strip() for h in table.header], table.rows, table.number
    if len(header) < 2:
        raise MeasurementError(source, ["line 1: expected a time column and at least one series column"])

    claimed: dict[str, int] = {}
    missing: list[tuple[str, set[str]]] = []
    for node, spec in specs.items():
        names = spec.names()
        found = [i for i, h in enumerate(header[1:], start=1) if h in names]
        if len(found) > 1:
            problems.append(f"columns {', '.join(f'{i + 1} ({header[i]!r})' for i in found)} all name device {node}: "
                            "keep one (which one the model reads would be a guess)")
        if found:
            claimed[node] = found[0]
        elif spec.required:
            missing.append((node, names))
    readers = defaultdict(list)  # column → the devices it is claimed by
    for node, column in claimed.items():
        readers[column].append(node)
    problems += [f"column {column + 1} ({header[column]!r}) is claimed by {len(nodes)} devices, {', '.join(nodes)}: "
                 "each would be fitted to the same readings; give each its own column (its gt:timeSeriesId)"
                 for column, nodes in sorted(readers.items()) if len(nodes) > 1]
    unknown = sorted(set(range(1, len(header))) - set(claimed.values()))
    for node, names in missing:
        near = _near_header(names, [header[i] for i in unknown])
        hint = f"; column {header.index(near) + 1}, {near!r}, is near: a misspelling?" if near else ""
        problems.append(
            f"no column for {node} (expected a header named {' or '.join(sorted(repr(n) for n in names))}{hint})"
        )
    if unknown:
        warnings.append(f"columns no device of the model claims: {', '.join(header[i] for i in unknown)} "
                        "(an operating filter may read them)")
    other_index = {header[i]: i for i in unknown if header[i] and header.count(header[i]) == 1}
    others = {name: np.full(len(rows), np.nan) for name in other_index}

    times: list[datetime] = []
    unreadable: set[int] = set()
    first_with_offset: dict[bool, tuple[int, str]] = {}
    values = {node: np.full(len(rows), np.nan) for node in claimed}
    error_cells: dict[str, int] = {}
    misshapen: list[str] = []
    for line, row in enumerate(rows, start=2):
        if not row or all(not c.strip() for c in row):
            problems.append(f"line {line}: empty row")
            continue
        if len(row) != len(header):  # a cell added or lost shifts every cell after it into another column
            misshapen.append(f"line {line}: {len(row)} fields, the header has {len(header)}")
        try:
            stamp, with_offset = _parsed_timestamp(row[0])
            times.append(stamp)
            first_with_offset.setdefault(with_offset, (line, row[0].strip()))
            if not PLAUSIBLE_YEARS[0] <= stamp.year <= PLAUSIBLE_YEARS[1]:
                problems.append(f"line {line}, column {header[0]!r}: time stamp {row[0].strip()!r} lies outside the "
                                f"years {PLAUSIBLE_YEARS[0]}–{PLAUSIBLE_YEARS[1]} (a glitch of the export?)")
        except ValueError as exc:
            problems.append(f"line {line}, column {header[0]!r}: {exc}")
            unreadable.add(len(times))  # said once: its placeholder is no stamp out of order
            times.append(datetime.min)
        for node, column in claimed.items():
            cell = row[column].strip() if column < len(row) else ""
            if cell.lower() in _MISSING:
                continue
            if cell.startswith("#"):
                error_cells[header[column]] = error_cells.get(header[column], 0) + 1
                continue
            try:
                value = as_number(cell)
            except ValueError:
                problems.append(f"line {line}, column {header[column]!r}: {cell!r} is not a number")
                continue
            if np.isfinite(value):
                values[node][line - 2] = value
            else:
                problems.append(f"line {line}, column {header[column]!r}: {cell!r} is not a finite number")
        for name, column in other_index.items():
            try:
                others[name][line - 2] = as_number(row[column])
            except (IndexError, ValueError):
                pass  # not the model's: a word or an empty cell there is no number, and no error
    problems += misshapen[:10] + ([f"… and {len(misshapen) - 10} more lines whose fields do not match the header"]
                                  if len(misshapen) > 10 else [])
    if len(times) < 2:
        problems.append("fewer than two data rows")
    if len(first_with_offset) == 2:
        (with_line, with_text), (without_line, without_text) = first_with_offset[True], first_with_offset[False]
        problems.append(f"line {with_line}: time stamp {with_text!r} has a UTC offset but line {without_line}'s "
                        f"{without_text!r} has none: give every stamp an offset, or none")
    warnings += [f"column {name!r}: {count} spreadsheet error cell(s) read as missing" for name, count in error_cells.items()]
    stamps = np.array(times, dtype="datetime64[s]")
    if len(times) >= 2:
        steps = np.diff(stamps).astype(np.int64)
        unread = np.zeros(len(times), dtype=bool)
        unread[sorted(unreadable)] = True
        readable = ~(unread[:-1] | unread[1:])  # neither stamp of the step a placeholder
        for i in np.flatnonzero((steps <= 0) & readable)[:10]:  # in the file's order
            problems.append(f"line {i + 3}: duplicate time stamp {stamps[i + 1]}" if steps[i] == 0 else
                            f"line {i + 3}: time stamp {stamps[i + 1]} is before the previous one ({stamps[i]})")
    converted: dict[str, np.ndarray] = {}
    for node, column in claimed.items():
        spec = specs[node]
        if spec.unit is None:
            problems.append(f"column {header[column]!r}: device {node} declares no unit "
                            "(saref:isMeasuredIn, in Brick brick:hasUnit)")
            continue
        try:
            converted[node] = convert(values[node], spec.unit, spec.port_unit,
                                      where=f"column {header[column]!r}, in the unit that {node} declares")
        except UnitError as exc:
            problems.append(str(exc))
            continue
        if spec.port_unit == "1":
            _check_fraction(converted[node], f"column {header[column]!r}", spec.unit, problems, warnings)
    if problems:
        unknown = [i for i, p in enumerate(problems) if p.endswith(KNOWN_UNITS)]  # the known units said once
        problems = [p.removesuffix(KNOWN_UNITS) if i in unknown[:-1] else p for i, p in enumerate(problems)]
        raise MeasurementError(source, problems)
    step_s = float(round(np.median(np.diff(stamps).astype(np.int64))))  # whole seconds, as the grid
    _check_grid_size(source, stamps, step_s)
    for node, column in claimed.items():
        if not specs[node].holds_values:
            warnings += [f"column {header[column]!r}: {text}" for text in frozen_spans(
                stamps, values[node], specs[node].unit or "", min_span_s=frozen_after_s,
                max_gap_s=max_gap_steps * step_s)]

    regular = np.all(np.diff(stamps).astype(np.int64) == step_s)
    if not regular:
        grid = np.arange(stamps[0], stamps[-1] + np.timedelta64(1, "s"), np.timedelta64(int(step_s), "s"))
        t_old = (stamps - stamps[0]).astype(np.int64).astype(float)
        t_new = (grid - stamps[0]).astype(np.int64).astype(float)
        spacings = np.diff(stamps).astype(np.int64)
        widest = int(np.argmax(spacings))
        warnings.append(
            f"irregular time stamps ({int(np.sum(spacings != step_s))} spacings differ from the median step "
            f"{step_s:g} s, the widest {_duration_text(float(spacings[widest]))} after "
            f"{_stamp_text(stamps[widest], True in first_with_offset)}): resampled linearly to {grid.size} steps, "
            f"the gaps longer than {max_gap_steps} steps left empty"
        )
        # a gap longer than the limit stays a gap: interpolate a grid point only between two of the
        # series' own values at most max_gap_steps + 1 steps apart (a run of empty cells is as much
        # a gap as a run of missing rows); a grid point on a row keeps the row's value
        limit_s = (max_gap_steps + 1) * step_s

        def on_grid(series: np.ndarray, hold: bool = False) -> np.ndarray:
            finite = np.isfinite(series)
            t_known, y_known = t_old[finite], series[finite]
            resampled = np.full(grid.size, np.nan)
            if t_known.size:
                after = np.searchsorted(t_known, t_new, side="right")  # first known value after the point
                before = np.clip(after - 1, 0, None)
                on_row = (after > 0) & (t_known[before] == t_new)
                later = np.clip(after, 0, t_known.size - 1)
                between = (after > 0) & (after < t_known.size)
                close = between & (t_known[later] - t_known[before] <= limit_s)
                if hold:  # the nearer row's value: a schedule steps, and a jittered stamp is no step
                    nearer = np.where(t_known[later] - t_new < t_new - t_known[before], later, before)
                    resampled[close] = y_known[nearer[close]]
                else:
                    resampled[close] = np.interp(t_new[close], t_known, y_known)
                resampled[on_row] = y_known[before[on_row]]
            return resampled

        converted = {node: on_grid(series, specs[node].steps) for node, series in converted.items()}
        others = {name: on_grid(series) for name, series in others.items()}
        stamps = grid
    unfilled = defaultdict(list)  # (runs, where the series is missing) → the devices with those gaps
    for node in list(converted):
        gaps = np.isnan(converted[node])
        converted[node], long_runs = _fill_short_gaps(converted[node], max_gap_steps, hold=specs[node].steps)
        filled = gaps & ~np.isnan(converted[node])
        if filled.any():
            how = "holding the last value" if specs[node].steps else "interpolating"
            warnings.append(f"column {header[claimed[node]]!r}: {int(filled.sum())} missing step(s) filled by {how} "
                            f"(the first at {_stamp_text(stamps[int(np.argmax(filled))], True in first_with_offset)})")
        if long_runs:
            unfilled[(long_runs, np.isnan(converted[node]).tobytes())].append(node)
    for (long_runs, _), nodes in unfilled.items():
        missing, names = np.isnan(converted[nodes[0]]), [header[claimed[node]] for node in nodes]
        columns = f"column {names[0]!r}" if len(names) == 1 else f"{len(names)} columns ({', '.join(map(repr, names))})"
        warnings.append(
            f"{columns}: {long_runs} gap(s) longer than {max_gap_steps} steps left unfilled ({int(missing.sum())} "
            f"steps, the first from {_stamp_text(stamps[int(np.argmax(missing))], True in first_with_offset)})"
        )
    return MeasuredData(
        timestamps=stamps, step_s=step_s, series=converted,
        units={n: specs[n].port_unit for n in converted}, source=source,
        columns={n: header[c] for n, c in claimed.items()}, warnings=tuple(warnings),
        source_units={n: specs[n].unit for n in converted}, utc=True in first_with_offset, other_columns=others,
    )


def frozen_spans(stamps: np.ndarray, values: np.ndarray, unit: str, *, min_span_s: float,
                 max_gap_s: float = np.inf) -> list[str]:
    """One sentence per span where ``values`` (in ``unit``, at ``stamps`` datetime64) hold exactly
    one non-zero value for at least ``min_span_s`` seconds: a frozen point (a BMS that keeps the
    last reading of a failed sensor or a lost connection; a live sensor's reading flickers by its
    resolution at least). Zero is exempt: a flow or power meter reads a true zero with the fan off.
    Readings more than ``max_gap_s`` apart (a day missing from the file, a long run of empty cells)
    do not make one span: two equal readings across a gap are no evidence of a hold."""
    finite = np.isfinite(values)
    index = np.flatnonzero(finite)
    if index.size < 2:
        return []
    kept = values[index]
    gap = np.diff(stamps[index]).astype("timedelta64[s]").astype(float) > max_gap_s
    starts = np.flatnonzero(np.r_[True, (kept[1:] != kept[:-1]) | gap])
    stops = np.r_[starts[1:], kept.size]
    found = []
    for start, stop in zip(starts, stops):
        first, last = stamps[index[start]], stamps[index[stop - 1]]
        span_s = float((last - first) / np.timedelta64(1, "s"))
        if span_s >= min_span_s and kept[start] != 0.0:
            found.append(f"holds {f'{kept[start]:g} {unit_label(unit)}'.rstrip()} exactly from "
                         f"{_stamp_text(first, False)} to {_stamp_text(last, False)} "
                         f"({span_s / 86400.0:.1f} days): a frozen point? The model takes it as measured")
    return found
