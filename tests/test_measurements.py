"""The measured-data contract: time formats, column matching, units, gaps, clear errors."""

import numpy as np
import pytest

from service.measurements import MeasurementError, SeriesSpec, parse_timestamp, read_measurements

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


def test_every_problem_is_reported_with_line_and_column(tmp_path):
    path = _write(tmp_path, "time,SAT,valve,extra\n2025-01-01 00:00,20,abc,1\n2025-01-01 00:00,21,10,1\n2024-12-31 23:50,21,10,1\n")
    with pytest.raises(MeasurementError) as info:
        read_measurements(path, SPECS)
    text = str(info.value)
    assert "line 2, column 'valve': 'abc' is not a number" in text
    assert "line 3: duplicate time stamp" in text
    assert "line 4: time stamp" in text and "before the previous one" in text
    with pytest.raises(MeasurementError, match="no column for https://example.org/x#valve"):
        read_measurements(_write(tmp_path, "time,SAT\n2025-01-01 00:00,20\n2025-01-01 00:10,21\n"), SPECS)


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


def test_windows_outside_the_data_are_refused(tmp_path):
    data = read_measurements(_write(tmp_path, "time,SAT,valve\n2025-01-01 00:00,50,0\n2025-01-01 00:10,50,0\n2025-01-01 00:20,50,0\n"), SPECS)
    assert data.window("2025-01-01 00:10", None) == slice(1, 3)
    with pytest.raises(ValueError, match="outside the data"):
        data.window("2026-01-01", "2026-01-02")
