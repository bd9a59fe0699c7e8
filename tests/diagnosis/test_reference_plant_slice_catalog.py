"""The CI slice of the validation matrix (docs/validation.md): a few cells, one seed each, diagnosed
on data from the independent reference plant (tests/reference_plant, physics that shares no code
with service/), so a wiring defect both sides would share fails here rather than only in the bench.
This module: a subtle stuck valve, a clear sensor offset, a clear duct heat exchange with the plant room
(which the graph does not describe) and a water sensor's two-hour lag (fault-free data and a leak:
``test_reference_plant_slice.py``).

One seed a cell is a regression guard, not a rate: the rates are the bench's
(``python tests/bench/bench_validation_matrix.py``). A cell graphtwin gets wrong is marked
``xfail(strict=True)`` with the reason: when it starts passing, the mark must go.
"""

import pytest

from tests.bench.bench_validation_matrix import Run, cell_run, diagnose_run

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(("fault", "size"), [("valve_stuck", "subtle"), ("sensor_offset", "clear"),
                                           ("duct_heat_exchange", "clear")])
def test_the_injected_fault_is_named_first_and_significant_at_its_node(fault, size):
    row = diagnose_run(cell_run(fault, size))
    assert row["right_first"], (row["top"], row["true_rank"], row["truth"])


def test_a_water_sensor_that_lost_its_contact_is_named_with_its_time_constant():
    """A two-hour lag (the sensor off its pipe) leaves 4σ at the coil outlet water: named first and
    significant, τ inside its prior (on the 30-minute prior alone it fitted at that bound, was
    demoted and ranked 18th)."""
    row = diagnose_run(Run("catalog", "sensor_lag", "2 h", 7200.0, 0))
    assert row["right_first"], (row["top"], row["true_rank"], row["truth"])
    lag = next(c for c in row["candidates"] if c["candidate"] == row["top"])
    assert not lag["demoted"] and 3600.0 < lag["estimates"]["time_constant"] < 7200.0, lag
