"""Operating filters: conditions in the file's units, all must hold, unmeasured steps excluded."""

import re

import numpy as np
import pytest

from service.data.measurements import SeriesSpec, read_measurements
from service.data.operating_filter import operating_mask, parse_condition

SPECS = {
    "https://example.org/x#sat": SeriesSpec("https://example.org/x#sat", "SAT (°F)", "http://qudt.org/vocab/unit/DEG_F", "degC"),
    "https://example.org/x#fan": SeriesSpec("https://example.org/x#fan", None, "http://qudt.org/vocab/unit/PERCENT", "1"),
}


def test_conditions_read_in_the_columns_own_units_and_all_must_hold(tmp_path):
    path = tmp_path / "data.csv"
    path.write_text("time,SAT (°F),fan\n" + "".join(
        f"2026-01-01 00:{m:02d},{sat},{fan}\n"
        for m, (sat, fan) in enumerate([(50, 0), (60, 10), (70, 80), (80, 100), (90, ""), (100, "")])))
    data = read_measurements(path, SPECS, max_gap_steps=0)
    # percent in the file, a fraction in the model: 5 % is 0.05
    assert operating_mask(data, ["fan > 5"]).tolist() == [False, True, True, True, False, False]
    # °F in the file, °C in the model: 65 °F is 18.3 °C; both conditions must hold
    assert operating_mask(data, ["fan >= 10", "SAT (°F) < 75"]).tolist() == [False, True, True, False, False, False]
    assert operating_mask(data, []).all()
    assert str(parse_condition(" SAT (°F) <= -1.5e1 ")) == "SAT (°F) <= -15"


def test_a_regime_rule_as_printed_is_a_condition_its_unit_checked(tmp_path):
    """The regime rules name a device with spaces, write ≤ and ≥ and end with the column's unit: so
    taken, they select what the header form selects; a unit that is not the column's is refused."""
    specs = SPECS | {"https://example.org/x#supply_fan": SeriesSpec("https://example.org/x#supply_fan", "fan",
                                                                   "http://qudt.org/vocab/unit/PERCENT", "1")}
    specs.pop("https://example.org/x#fan")
    path = tmp_path / "data.csv"
    path.write_text("time,SAT (°F),fan\n" + "".join(f"2026-01-01 00:{m:02d},{50 + 10 * m},{20 * m}\n" for m in range(6)))
    data = read_measurements(path, specs)
    assert (operating_mask(data, ["supply fan ≤ 60 %", "SAT (°F) ≥ 55 °F"]).tolist()
            == operating_mask(data, ["fan <= 60", "SAT (°F) >= 55"]).tolist() == [False, True, True, True, False, False])
    with pytest.raises(ValueError, match=r"the column 'fan' is in %, not °C"):
        operating_mask(data, ["supply_fan > 5 °C"])
    assert operating_mask(data, ["SAT (°F) ≥ 55 DEG_F"]).tolist() == operating_mask(data, ["SAT (°F) >= 55"]).tolist()
    with pytest.raises(ValueError, match=r"one condition per --only-when"):
        operating_mask(data, ["supply fan ≤ 60 % and SAT (°F) ≥ 55 °F"])
    with pytest.raises(ValueError, match=r"a rule joined by 'or' is no filter .*: give one of its bracketed branches"):
        operating_mask(data, ["(fan ≤ 60 and SAT (°F) ≥ 55) or fan > 90"])
    # a column whose name holds an operator, and numbers no unit may split
    assert parse_condition("dP > 0 > 0").column == "dP > 0" and parse_condition("temp > 5e-1").value == 0.5
    for split in ("fan > 5,5", "fan > 1.5.2", "fan ≥ 0.5 1"):
        with pytest.raises(ValueError, match="expected COLUMN OP NUMBER"):
            parse_condition(split)


def test_bad_conditions_are_named(tmp_path):
    path = tmp_path / "data.csv"
    path.write_text("time,SAT (°F),fan\n2026-01-01 00:00,50,0\n2026-01-01 00:01,60,10\n")
    data = read_measurements(path, SPECS)
    with pytest.raises(ValueError, match=r"'fan = 5': expected COLUMN OP NUMBER"):
        operating_mask(data, ["fan = 5"])
    for doubled in ("fan >> 5", "fan => 5", "fan <> 5"):  # a bad operator, not a column 'fan >'
        with pytest.raises(ValueError, match=re.escape(f"{doubled!r}: expected COLUMN OP NUMBER")):
            operating_mask(data, [doubled])
    with pytest.raises(ValueError, match=r"on 'pump'.*known: SAT \(°F\), fan"):
        operating_mask(data, ["pump > 0"])
    with pytest.raises(ValueError, match="no step .* satisfies fan > 50"):
        operating_mask(data, ["fan > 50"])
    assert np.all(operating_mask(data, ["fan > -1"]))


def test_a_column_the_model_does_not_read_filters_in_its_own_numbers(tmp_path):
    """A fan status column, say: the BMS export has it, the model does not read it."""
    path = tmp_path / "data.csv"
    path.write_text("time,SAT (°F),fan,Fan Status,Comment\n" + "".join(
        f"2026-01-01 00:{m:02d},{60 + m},50,{status},{word}\n"
        for m, (status, word) in enumerate([(0, "off"), (1, "on"), (1, ""), ("", "x"), (0, "off")])))
    data = read_measurements(path, SPECS, max_gap_steps=0)
    assert operating_mask(data, ["Fan Status > 0.5"]).tolist() == [False, True, True, False, False]
    assert operating_mask(data, ["Fan Status > 0.5", "SAT (°F) < 62"]).tolist() == [False, True, False, False, False]
    with pytest.raises(ValueError, match="operating condition on 'Comment': that column of .* holds no number"):
        operating_mask(data, ["Comment > 0"])
    irregular = tmp_path / "irregular.csv"  # resampled on the grid with the model's columns
    irregular.write_text("time,SAT (°F),fan,Fan Status\n2026-01-01 00:00,60,50,0\n2026-01-01 00:10,61,50,1\n"
                         "2026-01-01 00:15,62,50,1\n2026-01-01 00:20,63,50,1\n2026-01-01 00:30,64,50,1\n")
    data = read_measurements(irregular, SPECS)
    assert data.n_steps == 5 and data.other_columns["Fan Status"] == pytest.approx([0.0, 0.75, 1.0, 1.0, 1.0])  # 7.5 min grid
    assert data.select("2026-01-01 00:15", None).other_columns["Fan Status"].tolist() == [1.0] * 3
