"""The CI slice of the validation matrix (docs/validation.md): a few cells, one seed each, diagnosed
on data from the independent reference plant (tests/reference_plant, physics that shares no code
with service/), so a wiring defect both sides would share fails here rather than only in the bench.

One seed a cell is a regression guard, not a rate: the rates are the bench's
(``python tests/bench/bench_validation_matrix.py``). The cell graphtwin gets wrong today is marked
``xfail(strict=True)``: when it starts passing, the mark must go.
"""

import pytest

from tests.bench.bench_validation_matrix import Run, diagnose_run
from tests.reference_plant import FAULTS

pytestmark = pytest.mark.slow


def _cell(fault: str | None, size: str = "clear") -> dict:
    if fault is None:
        return diagnose_run(Run("fault-free", None, "-", 0.0, 0))
    return diagnose_run(Run("catalog", fault, size, getattr(FAULTS[fault], size), 0))


def test_fault_free_plant_data_raise_no_significant_effect():
    row = _cell(None)
    assert not row["any_significant"], row


@pytest.mark.parametrize(("fault", "size"), [("valve_stuck", "subtle"), ("sensor_offset", "clear")])
def test_the_injected_fault_is_named_first_and_significant_at_its_node(fault, size):
    row = _cell(fault, size)
    assert row["right_first"], (row["top"], row["true_rank"], row["truth"])


@pytest.mark.xfail(strict=True, reason="issue 32 (1): on a real leak the command and position read 0 while water "
                                       "flows through the seat; the library's ValveLeakage changes the position "
                                       "reading too, so a constant heat gain at the coil wins")
def test_a_leaking_valve_is_named_first():
    row = _cell("valve_leakage")
    assert row["right_first"], (row["top"], row["true_rank"])
