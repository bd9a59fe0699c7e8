"""The measured-data contract: time formats, column matching, units, gaps, clear errors."""

from dataclasses import replace

import numpy as np
import pytest

from service.data.csv_output import write_comparison_csv
from service.data.measurements import (
    MeasurementError,
    SeriesSpec,
    parse_timestamp,
    read_measurements,
)

SPECS = {
    "https://example.org/x#sat": SeriesSpec("https://example.org/x#sat", "SAT ", "http://qudt.org/vocab/unit/DEG_F", "degC"),
    "https://example.org/x#valve": SeriesSpec("https://example.org/x#valve", None, "http://qudt.org/vocab/unit/PERCENT", "1"),
}


def _write(tmp_path, text):
    path = tmp_path / "data.csv"
    path.write_text(text)
    return path


def test_bms_time_format_columns_by_series_id_and_local_name(tmp_path):
    path = _write(tmp_path, "Datetime, SAT ,valve\n9/12/17 0:00,68,50\n9/12/17 0:01,69.8,\n9/12/17 0:02,71.6,100\n")
    data = read_measurements(path, SPECS)
    assert data.step_s == 60.0 and data.n_steps == 3
    assert data.series["https://example.org/x#sat"] == pytest.approx([20.0, 21.0, 22.0])
    assert data.series["https://example.org/x#valve"] == pytest.approx([0.5, 0.75, 1.0])  # a one-step gap interpolated
    assert str(data.timestamps[0]) == "2017-09-12T00:00:00"
    assert parse_timestamp("2025-01-01T01:00:00+01:00").hour == 0


def test_a_windows_1252_export_is_read_and_a_binary_file_is_refused(tmp_path):
    spec = {"https://example.org/x#sat": SeriesSpec("https://example.org/x#sat", "SAT (°F)", "http://qudt.org/vocab/unit/DEG_F", "degC")}
    path = tmp_path / "bms.csv"
    path.write_bytes("time,SAT (°F)\n2025-01-01 00:00,50\n2025-01-01 00:10,68\n".encode("cp1252"))
    data = read_measurements(path, spec)
    assert data.series["https://example.org/x#sat"] == pytest.approx([10.0, 20.0])
    assert "not UTF-8 (line 1: byte 0xb0): read as Windows-1252" in data.warnings
    path.write_bytes(b"time,SAT\n2025-01-01 00:00,50\n\x81\x00\x9d")
    with pytest.raises(MeasurementError, match="line 3: byte 0x81 at offset 29 is neither UTF-8 nor Windows-1252"):
        read_measurements(path, spec)


def test_every_problem_is_reported_with_line_and_column(tmp_path):
    path = _write(tmp_path, "time,SAT,valve,extra\n2025-01-01 00:00,20,abc,1\n2025-01-01 00:00,21,10,1\n2024-12-31 23:50,-inf,10,1\n")
    with pytest.raises(MeasurementError) as info:
        read_measurements(path, SPECS)
    text = str(info.value)
    assert "line 2, column 'valve': 'abc' is not a number" in text
    assert "line 3: duplicate time stamp" in text
    assert "line 4: time stamp" in text and "before the previous one" in text
    assert "line 4, column 'SAT': '-inf' is not a finite number" in text
    backwards_then_repeated = "time,SAT,valve\n2025-01-01 00:10,20,1\n2025-01-01 00:00,20,1\n2025-01-01 00:00,20,1\n"
    with pytest.raises(MeasurementError) as info:  # in the file's order, whatever the kind
        read_measurements(_write(tmp_path, backwards_then_repeated), SPECS)
    assert str(info.value).index("line 3: time stamp") < str(info.value).index("line 4: duplicate time stamp")
    with pytest.raises(MeasurementError, match="no column for https://example.org/x#valve"):
        read_measurements(_write(tmp_path, "time,SAT\n2025-01-01 00:00,20\n2025-01-01 00:10,21\n"), SPECS)


def test_a_misspelt_column_is_pointed_at_and_a_missing_file_said_so(tmp_path):
    with pytest.raises(MeasurementError) as info:
        read_measurements(_write(tmp_path, "time,SAT ,vlave,other\n2025-01-01 00:00,20,1,2\n2025-01-01 00:10,21,1,2\n"),
                          SPECS)
    assert "no column for https://example.org/x#valve" in str(info.value)
    assert "column 3, 'vlave', is near: a misspelling?" in str(info.value)
    with pytest.raises(MeasurementError) as info:  # a unit in brackets after the name: that column, not a look-alike
        read_measurements(_write(tmp_path, "time,SAT ,valve-sp,valve (%)\n2025-01-01 00:00,20,1,2\n"
                                           "2025-01-01 00:10,21,1,2\n"), SPECS)
    assert "column 4, 'valve (%)', is near: a misspelling?" in str(info.value)
    with pytest.raises(MeasurementError) as info:  # nothing near: no guess
        read_measurements(_write(tmp_path, "time,SAT ,flow\n2025-01-01 00:00,20,1\n2025-01-01 00:10,21,1\n"), SPECS)
    assert "misspelling" not in str(info.value)
    with pytest.raises(MeasurementError) as info:
        read_measurements(tmp_path / "nope.csv", SPECS)
    assert str(info.value) == f"{tmp_path / 'nope.csv'}:\n  - no such file"


def test_long_gaps_stay_gaps_and_irregular_steps_are_resampled(tmp_path):
    rows = ["time,SAT,valve"] + [f"2025-01-01 00:{m:02d},{50 + m},{m}" for m in range(0, 30)]
    rows[5:15] = [r.split(",")[0] + ",," + r.split(",")[2] for r in rows[5:15]]
    data = read_measurements(_write(tmp_path, "\n".join(rows)), SPECS, max_gap_steps=3)
    sat = data.series["https://example.org/x#sat"]
    assert np.isnan(sat[4:14]).all() and np.isfinite(sat[:4]).all()
    assert any("gap" in w for w in data.warnings)
    irregular = "time,SAT,valve\n2025-01-01 00:00,50,0\n2025-01-01 00:10,50,0\n2025-01-01 00:25,53,0\n2025-01-01 00:30,54,0\n"
    data = read_measurements(_write(tmp_path, irregular), SPECS)
    assert data.step_s == 10.0 * 60 and data.n_steps == 4 and any("resampled" in w for w in data.warnings)


def test_schedules_are_held_in_gaps_and_resampling_where_sensors_are_interpolated(tmp_path):
    """A setpoint steps: a gap holds its last value (zero-order hold) and a resampled grid point takes
    the nearer row's, where a temperature sensor's are interpolated."""
    specs = {**SPECS, "https://example.org/x#valve": replace(SPECS["https://example.org/x#valve"], holds_values=True, steps=True)}
    gap = "time,SAT,valve\n2025-01-01 00:00,50,0\n2025-01-01 00:01,,\n2025-01-01 00:02,,\n2025-01-01 00:03,53,60\n"
    data = read_measurements(_write(tmp_path, gap), specs)
    assert data.series["https://example.org/x#valve"] == pytest.approx([0.0, 0.0, 0.0, 0.6])
    assert data.series["https://example.org/x#sat"] == pytest.approx((np.array([50, 51, 52, 53]) - 32) / 1.8)
    assert "column 'SAT': 2 missing step(s) filled by interpolating (the first at 2025-01-01T00:01)" in data.warnings
    assert "column 'valve': 2 missing step(s) filled by holding the last value (the first at 2025-01-01T00:01)" in data.warnings
    # a stamp a minute off the 10-minute grid: the command takes the nearer row's value, the sensor ramps
    irregular = "time,SAT,valve\n2025-01-01 00:00,50,0\n2025-01-01 00:10,50,0\n2025-01-01 00:21,53,60\n2025-01-01 00:30,54,60\n"
    data = read_measurements(_write(tmp_path, irregular), specs)
    assert data.series["https://example.org/x#valve"] == pytest.approx([0.0, 0.0, 0.6, 0.6])
    assert data.series["https://example.org/x#sat"][2] == pytest.approx((50.0 + 3.0 * 10.0 / 11.0 - 32) / 1.8)


def test_windows_outside_the_data_are_refused(tmp_path):
    data = read_measurements(_write(tmp_path, "time,SAT,valve\n2025-01-01 00:00,50,0\n2025-01-01 00:10,50,0\n2025-01-01 00:20,50,0\n"), SPECS)
    assert data.window("2025-01-01 00:10", None) == slice(1, 3)
    with pytest.raises(ValueError, match="outside the data"):
        data.window("2026-01-01", "2026-01-02")
    assert data.window(None, "2025-01-01 00:30") == slice(0, 3)  # one step past the last stamp: a whole period
    with pytest.raises(ValueError, match=r"ends after the data .*\(2025-01-01T00:00 – 2025-01-01T00:20\)"):
        data.window("2025-01-01 00:10", "2025-01-02")  # a day asked of 20 minutes: not cut silently
    with pytest.raises(ValueError, match="starts before the data"):
        data.window("2024-12-31 23:00", "2025-01-01 00:10")
    with pytest.raises(ValueError, match=r"lies outside the data .*\(2025-01-01T00:00 – 2025-01-01T00:20\)"):
        data.window("2026-01-01", None)  # an open end after the data's: outside, not "the end is before the start"


def test_valid_mask_and_select_by_time(tmp_path):
    rows = ["time,SAT,valve"] + [f"2025-01-01 00:{m:02d},{50 + m},{m}" for m in range(0, 20)]
    rows[3:11] = [r.split(",")[0] + ",," + r.split(",")[2] for r in rows[3:11]]  # SAT lines 4–11: an 8-step gap
    data = read_measurements(_write(tmp_path, "\n".join(rows)), SPECS, max_gap_steps=5)
    assert data.valid.tolist() == [True] * 2 + [False] * 8 + [True] * 10
    part = data.select("2025-01-01 00:05", "2025-01-01 00:12:00")
    assert part.n_steps == 8 and str(part.timestamps[0]) == "2025-01-01T00:05:00"
    assert part.series["https://example.org/x#valve"] == pytest.approx(np.arange(5, 13) / 100)
    assert part.valid.tolist() == [False] * 5 + [True] * 3
    with pytest.raises(ValueError, match=r"lies outside the data .*2025-01-01T00:00 – 2025-01-01T00:19"):
        data.select("2024-06-01", "2024-06-02")
    with pytest.raises(ValueError, match="end is before the start"):
        data.select("2025-01-01 00:10", "2025-01-01 00:05")


def test_unit_problems_and_spreadsheet_errors_are_reported_by_column(tmp_path):
    text = "time,SAT,valve\n2025-01-01 00:00,50,#VALUE!\n2025-01-01 00:10,50,10\n2025-01-01 00:20,50,20\n"
    data = read_measurements(_write(tmp_path, text), SPECS)
    assert "column 'valve': 1 spreadsheet error cell(s) read as missing" in data.warnings
    assert np.isnan(data.series["https://example.org/x#valve"][0])  # a leading gap is not extrapolated
    wrong = {**SPECS, "https://example.org/x#valve": SeriesSpec("https://example.org/x#valve", None,
                                                                 "http://qudt.org/vocab/unit/KiloGM-PER-SEC", "1")}
    no_unit = {**SPECS, "https://example.org/x#sat": SeriesSpec("https://example.org/x#sat", "SAT", None, "degC")}
    with pytest.raises(MeasurementError, match=r"KiloGM-PER-SEC \(mass_flow\) to 1 \(fraction\) for column 'valve'"):
        read_measurements(_write(tmp_path, text), wrong)
    with pytest.raises(MeasurementError, match=r"column 'SAT': device https://example.org/x#sat declares no unit"):
        read_measurements(_write(tmp_path, text), no_unit)
    # two columns of unknown units: each named with its hint, the known units listed once, at the end
    unknown = {node: replace(spec, unit=spec.unit.replace("DEG_F", "DEG_FF").replace("PERCENT", "PERCNT"))
               for node, spec in SPECS.items()}
    with pytest.raises(MeasurementError) as both:
        read_measurements(_write(tmp_path, text), unknown)
    problems = both.value.problems
    assert len(problems) == 2 and "did you mean http://qudt.org/vocab/unit/DEG_F?" in problems[0]
    assert "did you mean http://qudt.org/vocab/unit/PERCENT?" in problems[1]
    assert "graphtwin knows the QUDT units" not in problems[0] and "graphtwin knows the QUDT units" in problems[1]
    extra = read_measurements(_write(tmp_path, "time,SAT,valve,extra\n2025-01-01 00:00,1,2,3\n2025-01-01 00:10,1,2,3\n"), SPECS)
    assert "columns no device of the model claims: extra (an operating filter may read them)" in extra.warnings
    assert extra.other_columns["extra"] == pytest.approx([3.0, 3.0])


def test_comparison_csv_writes_the_files_units_and_reads_back(tmp_path):
    text = "time,SAT,valve\n2025-01-01 00:00,68,50\n2025-01-01 00:10,,60\n2025-01-01 00:20,71.6,70\n"
    data = read_measurements(_write(tmp_path, text), SPECS)
    out = tmp_path / "out.csv"
    write_comparison_csv(out, data, {"https://example.org/x#sat": np.array([21.0, 22.0, 23.0])})  # °C
    lines = out.read_text().splitlines()
    assert lines[0] == "time,SAT,SAT (simulated),valve"
    assert lines[1] == "2025-01-01 00:00:00,68.0000,69.8000,50.0000"  # °F and % as in the file
    assert lines[2] == "2025-01-01 00:10:00,69.8000,71.6000,60.0000"  # the short gap as read (interpolated)
    again = read_measurements(out, SPECS)
    for node, values in data.series.items():
        np.testing.assert_allclose(again.series[node], values, rtol=1e-6)
    assert any("SAT (simulated)" in w for w in again.warnings)
    with pytest.raises(ValueError, match="does not hold: urn:other"):
        write_comparison_csv(out, data, {"urn:other": np.zeros(3)})
    with pytest.raises(ValueError, match=r"shape \(2,\), the data 3 steps"):
        write_comparison_csv(out, data, {"https://example.org/x#sat": np.zeros(2)})


def test_a_frozen_sensor_is_reported_but_a_held_command_or_a_zero_is_not(tmp_path):
    """Outdoor air frozen at 70.0 °F for two days (the school AHU's BMS did this), a valve command
    held at 40 % and a flow meter at 0 for as long: only the sensor is reported, once, in °F."""
    hours = np.arange(0, 96)
    sat = 50.0 + 10.0 * np.sin(hours / 5.0)
    sat[24:72] = 70.0
    specs = {
        **SPECS,
        "https://example.org/x#valve": replace(SPECS["https://example.org/x#valve"], holds_values=True),
        "https://example.org/x#flow": SeriesSpec("https://example.org/x#flow", None,
                                                 "http://qudt.org/vocab/unit/M3-PER-SEC", "m3/s"),
    }
    rows = "\n".join(f"2026-01-{1 + h // 24:02d} {h % 24:02d}:00,{sat[h]:.3f},40,{0.0 if 24 <= h < 72 else 1.2 + 0.01 * np.sin(h):.4f}"
                     for h in hours)
    data = read_measurements(_write(tmp_path, f"time,SAT,valve,flow\n{rows}\n"), specs)
    frozen = [w for w in data.warnings if "frozen" in w]
    assert frozen == ["column 'SAT': holds 70 °F exactly from 2026-01-02T00:00 to 2026-01-03T23:00 (2.0 days): "
                      "a frozen point? The model takes it as measured"]
    held = replace(specs["https://example.org/x#valve"], holds_values=False)
    assert any(w.startswith("column 'valve': holds 40 %") for w in read_measurements(
        _write(tmp_path, f"time,SAT,valve,flow\n{rows}\n"), {**specs, held.node: held}).warnings)


def test_two_equal_readings_across_a_missing_day_are_no_frozen_point(tmp_path):
    """FLEXLAB's files skip whole days: the last reading of one day and the first of the day after
    next happened to be equal — a gap in the file, not a held value."""
    rows = [f"2017-09-12 23:{m:02d},{60.0 + 0.1 * (m % 7):.1f},10" for m in range(50, 60)]
    rows += [f"2017-09-14 00:{m:02d},{60.0 + 0.1 * ((m + 3) % 7):.1f},10" for m in range(0, 10)]  # 9/13 absent
    data = read_measurements(_write(tmp_path, "time,SAT,valve\n" + "\n".join(rows) + "\n"), SPECS)
    assert not [w for w in data.warnings if "frozen" in w]


SAT_ONLY = {"https://example.org/x#sat": SPECS["https://example.org/x#sat"]}


def _sat_csv(stamps: list[str], cells: list[str]) -> str:
    return "time,SAT \n" + "".join(f"{t},{c}\n" for t, c in zip(stamps, cells, strict=True))


def _ten_minute_stamps(n: int, skip: int | None = None) -> list[str]:
    return [f"2025-01-01 {i * 10 // 60:02d}:{i * 10 % 60:02d}" for i in range(n) if i != skip]


def test_empty_cells_stay_a_gap_in_an_irregular_file_as_in_a_regular_one(tmp_path):
    """20 empty cells (200 min) and, in the second file, one row missing elsewhere: the resampling
    must not bridge the empty cells with a straight line, nor hold the last value past the end."""
    cells = [f"{68 + 0.1 * i:.1f}" for i in range(40)]
    cells[10:30] = [""] * 20
    cells[-3:] = ["", "", ""]
    sat = "https://example.org/x#sat"
    regular = read_measurements(_write(tmp_path, _sat_csv(_ten_minute_stamps(40), cells)), SAT_ONLY)
    irregular = read_measurements(_write(tmp_path, _sat_csv(_ten_minute_stamps(40, skip=35), cells[:35] + cells[36:])), SAT_ONLY)
    assert any("resampled" in w for w in irregular.warnings)
    for data in (regular, irregular):
        assert np.isnan(data.series[sat][10:30]).all() and np.isfinite(data.series[sat][:10]).all()
        assert np.isnan(data.series[sat][-3:]).all()
        assert any("gap(s) longer than 5 steps left unfilled" in w for w in data.warnings)
    assert irregular.series[sat][35] == pytest.approx((regular.series[sat][34] + regular.series[sat][36]) / 2)


def test_columns_with_the_same_long_gap_are_one_warning_that_says_where(tmp_path):
    """Two days joined in one file leave every column the same gap: one sentence naming the columns
    and where the gap starts, not one a column (the FLEXLAB recipe printed ten alike)."""
    stamps = _ten_minute_stamps(20) + [f"2025-01-02 {i * 10 // 60:02d}:{i * 10 % 60:02d}" for i in range(20)]
    rows = "".join(f"{t},{20 + i % 3},{0.1 * (i % 5):.1f}\n" for i, t in enumerate(stamps))
    data = read_measurements(_write(tmp_path, "time,SAT ,valve\n" + rows), SPECS)
    gaps = [w for w in data.warnings if "left unfilled" in w]
    assert gaps == ["2 columns ('SAT', 'valve'): 1 gap(s) longer than 5 steps left unfilled (124 steps, the first "
                    "from 2025-01-01T03:20)"], data.warnings


def test_a_row_just_before_a_long_row_gap_keeps_its_measured_value(tmp_path):
    stamps = ["2025-01-01 00:00", "2025-01-01 00:30", "2025-01-01 01:00", "2025-01-01 05:00", "2025-01-01 05:30",
              "2025-01-01 06:00"]
    data = read_measurements(_write(tmp_path, _sat_csv(stamps, ["68", "68.9", "69.08", "70", "71", "72"])), SAT_ONLY)
    sat = data.series["https://example.org/x#sat"]
    assert data.step_s == 1800 and sat[2] == pytest.approx(20.6) and np.isnan(sat[3:10]).all() and sat[10] == pytest.approx(21.1111, abs=1e-3)


def test_the_step_is_whole_seconds_and_the_grid_has_that_step(tmp_path):
    stamps = np.datetime64("2025-01-01T00:00") + np.cumsum([0] + [600, 601] * 10).astype("timedelta64[s]")
    data = read_measurements(_write(tmp_path, _sat_csv([str(t).replace("T", " ") for t in stamps], ["68"] * 21)), SAT_ONLY)
    assert data.step_s == 600 and set(np.diff(data.timestamps).astype(np.int64)) == {600}


def test_stamps_with_and_without_an_offset_in_one_file_are_refused(tmp_path):
    path = _write(tmp_path, _sat_csv(["2025-01-01T00:00:00+01:00", "2025-01-01T00:10:00", "2025-01-01T00:20:00"],
                                     ["68", "69", "70"]))
    with pytest.raises(MeasurementError, match="line 2: time stamp '2025-01-01T00:00:00\\+01:00' has a UTC offset "
                                               "but line 3's '2025-01-01T00:10:00' has none"):
        read_measurements(path, SAT_ONLY)


def test_a_semicolon_export_with_decimal_commas_and_european_dates_is_read(tmp_path):
    path = _write(tmp_path, "Zeit;SAT ;valve\n01.02.2025 00:00;68;50\n01.02.2025 00:10;69,8;75,5\n")
    data = read_measurements(path, SPECS)
    assert str(data.timestamps[0]) == "2025-02-01T00:00:00"
    assert data.series["https://example.org/x#sat"] == pytest.approx([20.0, 21.0])
    assert data.series["https://example.org/x#valve"] == pytest.approx([0.5, 0.755])


def test_a_percent_column_declared_as_a_fraction_is_refused_and_the_reverse_is_warned(tmp_path):
    valve = "https://example.org/x#valve"
    as_fraction = {valve: replace(SPECS[valve], unit="http://qudt.org/vocab/unit/UNITLESS")}
    path = _write(tmp_path, "time,valve\n2025-01-01 00:00,20\n2025-01-01 00:10,40\n")
    with pytest.raises(MeasurementError, match=r"column 'valve': reaches 40, but its unit \(1\) makes it a fraction \(0–1\): is it in percent"):
        read_measurements(path, as_fraction)
    path = _write(tmp_path, "time,valve\n2025-01-01 00:00,0.2\n2025-01-01 00:10,0.4\n")
    data = read_measurements(path, {valve: SPECS[valve]})
    assert data.series[valve] == pytest.approx([0.002, 0.004])
    assert any("never above 0.004 as a fraction" in w and "UNITLESS" in w for w in data.warnings)
    assert read_measurements(path, as_fraction).warnings == ()


def test_a_row_with_a_cell_added_or_lost_is_refused_by_line(tmp_path):
    """A cell added or lost shifts the cells after it into other columns: read as they stand, a
    temperature would land in the valve's column without a word."""
    rows = ["time,SAT,valve"] + [f"2025-01-01 00:{m:02d},{50 + m},{m}" for m in range(0, 30)]
    rows[3] += ",99"  # line 4: one field too many
    rows[6] = rows[6].rsplit(",", 1)[0]  # line 7: one too few
    with pytest.raises(MeasurementError) as info:
        read_measurements(_write(tmp_path, "\n".join(rows)), SPECS)
    assert "line 4: 4 fields, the header has 3" in str(info.value)
    assert "line 7: 2 fields, the header has 3" in str(info.value)
    rows = ["time,SAT,valve"] + [f"2025-01-01 00:{m:02d},{50 + m},0,{m}" for m in range(0, 30)]
    with pytest.raises(MeasurementError) as info:
        read_measurements(_write(tmp_path, "\n".join(rows)), SPECS)
    assert str(info.value).count("fields, the header has 3") == 10  # ten lines, then how many more
    assert "… and 20 more lines whose fields do not match the header" in str(info.value)


def test_two_columns_naming_one_device_are_refused(tmp_path):
    """Which of the two the model would read is a guess (the first, before: silently)."""
    path = _write(tmp_path, "time,SAT,valve,SAT\n2025-01-01 00:00,20,10,25\n2025-01-01 00:10,21,10,26\n")
    with pytest.raises(MeasurementError, match=r"columns 2 \('SAT'\), 4 \('SAT'\) all name device https://example.org/x#sat"):
        read_measurements(path, SPECS)
    path = _write(tmp_path, "time,SAT,valve,sat\n2025-01-01 00:00,20,10,25\n2025-01-01 00:10,21,10,26\n")  # by series id and local name
    with pytest.raises(MeasurementError, match=r"columns 2 \('SAT'\), 4 \('sat'\) all name device"):
        read_measurements(path, SPECS)


def test_one_column_claimed_by_two_devices_is_refused_and_a_header_in_another_case_is_pointed_at(tmp_path):
    """Two devices given one series id (a copy-paste slip) would each be fitted to the same readings
    (before: silently, a return-water sensor fitted to the supply air). A header that differs from
    the expected name only in case is named as the likely one."""
    specs = dict(SPECS) | {"https://example.org/x#hwr": SeriesSpec("https://example.org/x#hwr", "SAT ",
                                                                 "http://qudt.org/vocab/unit/DEG_F", "degC")}
    with pytest.raises(MeasurementError) as info:
        read_measurements(_write(tmp_path, "time,SAT ,valve\n2025-01-01 00:00,20,1\n2025-01-01 00:10,21,1\n"), specs)
    assert ("column 2 ('SAT') is claimed by 2 devices, https://example.org/x#sat, https://example.org/x#hwr: "
            "each would be fitted to the same readings") in str(info.value)
    specs = dict(SPECS) | {"https://example.org/x#hwr": SeriesSpec("https://example.org/x#hwr", None,
                                                                 "http://qudt.org/vocab/unit/DEG_F", "degC")}
    with pytest.raises(MeasurementError) as info:
        read_measurements(_write(tmp_path, "time,SAT ,valve,HWR\n2025-01-01 00:00,20,1,3\n2025-01-01 00:10,21,1,3\n"),
                          specs)
    assert "no column for https://example.org/x#hwr (expected a header named 'https://example.org/x#hwr' or 'hwr'; column 4, 'HWR', is near" in str(
        info.value)


def test_a_window_is_given_on_the_datas_clock(tmp_path):
    """Stamps with an offset are read as UTC: a window without one would be read as UTC too and land
    hours off without a word; a window with an offset on local stamps the same. Both are refused."""
    rows = "".join(f"2017-09-20T{h:02d}:00:00-07:00,{60 + h},{h}\n" for h in range(12))
    data = read_measurements(_write(tmp_path, "time,SAT,valve\n" + rows), SPECS)
    assert data.utc and str(data.timestamps[0]) == "2017-09-20T07:00:00"
    assert data.window("2017-09-20T02:00-07:00", "2017-09-20T05:00-07:00") == slice(2, 6)
    assert data.window("2017-09-20T09:00Z", None) == slice(2, 12)
    with pytest.raises(ValueError, match=r"the window's start '2017-09-20T02:00': the data .* give their time stamps with a "
                                         r"UTC offset \(read as UTC\); give it with an offset too"):
        data.window("2017-09-20T02:00", None)
    with pytest.raises(ValueError, match=r"window 2017-09-21T07:00 UTC – 2017-09-21T08:00 UTC lies outside the data "
                                         r".* \(2017-09-20T07:00 UTC – 2017-09-20T18:00 UTC\)"):
        data.window("2017-09-21T00:00-07:00", "2017-09-21T01:00-07:00")
    local = read_measurements(_write(tmp_path, "time,SAT,valve\n" + rows.replace("-07:00", "")), SPECS)
    assert not local.utc and local.window("2017-09-20T02:00", "2017-09-20T05:00") == slice(2, 6)
    with pytest.raises(ValueError, match=r"give their time stamps without a UTC offset \(local time\); give it without an offset"):
        local.window(None, "2017-09-20T05:00Z")


def test_a_glitched_time_stamp_is_refused_by_line_before_any_grid_is_built(tmp_path):
    """A BMS export's last stamp in year 9999 made the reader build a grid from 2025 to 9999 at the
    median step (17.8 GB before the server was killed); it is refused by line instead, as is a jump
    in time that would leave the grid mostly empty."""
    rows = "".join(f"2025-01-01 {h:02d}:{m:02d},20,50\n" for h in range(3) for m in range(0, 60, 10))
    with pytest.raises(MeasurementError, match=r"line 20, column 'time': time stamp '9999-12-31 23:50' lies outside "
                                               r"the years 1970–2100"):
        read_measurements(_write(tmp_path, "time,SAT,valve\n" + rows + "9999-12-31 23:50,20,50\n"), SPECS)
    with pytest.raises(MeasurementError, match=r"line 20: the time stamps jump from 2025-01-01T02:50 to "
                                               r"2060-01-01T00:00 \(1.84e\+06 steps of 600 s\): on a regular grid the "
                                               r"19 rows would stand for 1840753 steps"):
        read_measurements(_write(tmp_path, "time,SAT,valve\n" + rows + "2060-01-01 00:00,20,50\n"), SPECS)
    typo = rows.replace("2025-01-01 01:20", "2025-01-01 01:2O")  # a letter O: one problem, said once
    with pytest.raises(MeasurementError) as refused:
        read_measurements(_write(tmp_path, "time,SAT,valve\n" + typo), SPECS)
    assert "'2025-01-01 01:2O'" in str(refused.value) and "before the previous one" not in str(refused.value)
    gap = read_measurements(_write(tmp_path, "time,SAT,valve\n" + rows + "2025-01-01 05:00,20,50\n"), SPECS)
    assert gap.n_steps == 31  # a gap of hours is resampled as before, left a gap
