"""Time windows of the data as users write them: ``START/END``, either side may be empty."""

from __future__ import annotations

from service.data.measurements import parse_timestamp
from service.errors import InputError

__all__ = ["Window", "parse_window"]

Window = tuple[str | None, str | None]


def parse_window(text: str | None) -> Window:
    """``"START/END"`` (time stamps :func:`~service.data.measurements.parse_timestamp` reads, either side
    may be empty) → (start, end), checked before any data is read.

    :raises InputError: without exactly one ``/``, naming the side whose time stamp is unreadable,
        or when the end is before the start.
    """
    if text is None:
        return (None, None)
    if text.count("/") != 1:
        raise InputError(f"window {text!r}: write START/END, e.g. 2026-01-12/2026-01-15T23:50")
    start, end = (part.strip() or None for part in text.split("/"))
    parsed = {}
    for side, stamp in (("start", start), ("end", end)):
        if stamp is not None:
            try:
                parsed[side] = parse_timestamp(stamp)
            except ValueError as exc:
                raise InputError(f"window {text!r}, its {side}: {exc}") from None
    if len(parsed) == 2 and parsed["end"] < parsed["start"]:
        raise InputError(f"window {text!r}: the end is before the start")
    return start, end
