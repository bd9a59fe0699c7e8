"""Operating filters: compare the model with the measurements only where it is meant to hold.

A component model describes its equipment in operation: a mixing box mixes air streams, a coil heats
the air that flows through it. With the supply fan off there is no stream, and the sensors read
still air warmed by a coil or cooled by the casing, which no air-stream model reproduces (the school
AHU of ``../shared/realdata`` spends its nights so). An operating filter leaves such steps out of
the comparison: the model is still simulated through them (its boundary inputs are measured there),
but the targets' measurements there enter neither the calibration nor the metrics, regimes and
episodes.

A condition is ``COLUMN OP VALUE``: a column of the data file (one the model reads, a boundary input
or a target, by its header or the device's local name; or any other numeric column, a fan status
the model does not read), one of ``>``, ``>=``, ``<``, ``<=``, and a number in that column's own
unit (``"SF Spd Cmd (%) > 5"``: percent, as in the file). Several conditions must all hold. A step
where the column is not measured (or holds no number) does not satisfy the condition.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from service.data.measurements import MeasuredData
from service.graph.units import convert

__all__ = ["OperatingCondition", "parse_condition", "operating_mask"]

_OPERATORS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}
_CONDITION = re.compile(r"^\s*(?P<column>.+?)\s*(?P<op>>=|<=|>|<)\s*(?P<value>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)\s*$")


@dataclass(frozen=True)
class OperatingCondition:
    """``column op value``, ``value`` in the column's unit as written in the data file."""

    column: str
    op: str
    value: float

    def __str__(self) -> str:
        return f"{self.column} {self.op} {self.value:g}"


def parse_condition(text: str) -> OperatingCondition:
    """``"SF Spd Cmd (%) > 5"`` → the condition.

    :raises ValueError: naming the text and the expected form.
    """
    match = _CONDITION.match(text)
    if match is None:
        raise ValueError(f"operating condition {text!r}: expected COLUMN OP NUMBER with OP one of >, >=, <, <= "
                         "(e.g. 'SF Spd Cmd (%) > 5')")
    return OperatingCondition(match["column"], match["op"], float(match["value"]))


def _column_values(data: MeasuredData, condition: OperatingCondition) -> tuple[np.ndarray, float]:
    """The values ``condition``'s column holds and its threshold, in one unit: a column the model reads
    in its port unit (the threshold converted from the file's), another as the file gives it."""
    column = condition.column
    for node, header in data.columns.items():
        if header.strip() == column or node.replace("#", "/").rsplit("/", 1)[-1] == column:
            source_unit = data.source_units.get(node, data.units[node])
            threshold = float(convert([condition.value], source_unit, data.units[node],
                                      where=f"operating condition {condition}")[0])
            return data.series[node], threshold
    if column in data.other_columns:
        if not np.isfinite(data.other_columns[column]).any():
            raise ValueError(f"operating condition on {column!r}: that column of {data.source} holds no number")
        return data.other_columns[column], condition.value
    known = ", ".join(sorted({h.strip() for h in data.columns.values()} | set(data.other_columns)))
    raise ValueError(f"operating condition on {column!r}: {data.source} has no numeric column of that name "
                     f"(known: {known})")


def operating_mask(data: MeasuredData, conditions: Sequence[OperatingCondition | str]) -> np.ndarray:
    """``ndarray[n_steps]`` of bool: the steps where every condition holds (all steps for none).

    :raises ValueError: a malformed condition or a column the file does not have (or holds no number in).
    """
    mask = np.ones(data.n_steps, dtype=bool)
    for condition in conditions:
        condition = parse_condition(condition) if isinstance(condition, str) else condition
        values, threshold = _column_values(data, condition)
        with np.errstate(invalid="ignore"):
            mask &= np.isfinite(values) & _OPERATORS[condition.op](values, threshold)
    if not mask.any():
        raise ValueError(f"no step of {data.source} satisfies {' and '.join(map(str, conditions))}")
    return mask

