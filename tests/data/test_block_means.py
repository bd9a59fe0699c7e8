"""Block means of a BMS log: clock-aligned blocks the log covers whole, non-numbers left out."""

import csv

import pytest
from typer.testing import CliRunner

from service.cli import app
from service.data.block_means import write_block_means
from service.errors import InputError, MeasurementError


def _log(path, minutes: range, day: str = "9/12/2017", first_cell=lambda m: str(float(m))):
    lines = "".join(f"{day} {m // 60}:{m % 60:02d},{first_cell(m)},on\n" for m in minutes)
    path.write_text("Datetime,T,status\n" + lines)
    return path


def _rows(path):
    with path.open(newline="") as handle:
        return list(csv.reader(handle))


def test_blocks_are_clock_aligned_means_of_whole_blocks_stamped_with_their_start(tmp_path):
    # 00:07 to 01:02: the blocks 00:15, 00:30 and 00:45 are whole; 00:00 and 01:00 are not
    source = _log(tmp_path / "log.csv", range(7, 63), first_cell=lambda m: "#VALUE!" if m == 20 else str(float(m)))
    assert write_block_means(source, tmp_path / "out.csv", 15) == 3
    header, *rows = _rows(tmp_path / "out.csv")
    assert header == ["Datetime", "T", "status"]
    assert [r[0] for r in rows] == ["2017-09-12 00:15:00", "2017-09-12 00:30:00", "2017-09-12 00:45:00"]
    without_20 = [m for m in range(15, 30) if m != 20]  # a spreadsheet error is left out of the mean
    assert float(rows[0][1]) == pytest.approx(sum(without_20) / len(without_20))
    assert float(rows[1][1]) == pytest.approx(37.0) and rows[1][2] == ""  # a column with no number: empty


def test_a_european_export_is_read_as_the_measurement_contract_reads_it(tmp_path):
    source = tmp_path / "log.csv"  # semicolons, decimal commas, Windows-1252 (°)
    source.write_bytes("Zeit;T (°C)\n1.2.2026 0:00;20,5\n1.2.2026 0:10;21,5\n".encode("cp1252"))
    assert write_block_means(source, tmp_path / "out.csv", 20) == 1
    assert _rows(tmp_path / "out.csv")[1] == ["2026-02-01 00:00:00", "21.0"]


def test_days_are_kept_by_date_and_bad_input_is_named(tmp_path):
    source = tmp_path / "log.csv"
    source.write_text("t,T\n" + "".join(f"2026-01-0{d}T{h:02d}:00,{d}\n" for d in (1, 2) for h in range(24)))
    assert write_block_means(source, tmp_path / "out.csv", 120, {"2026-01-02"}) == 12
    assert {r[1] for r in _rows(tmp_path / "out.csv")[1:]} == {"2.0"}
    with pytest.raises(InputError, match="blocks of 90 min: give a positive whole multiple of the log's step"):
        write_block_means(source, tmp_path / "out.csv", 90)
    with pytest.raises(MeasurementError, match="no rows on 2026-01-03 \\(the log runs from 2026-01-01 00:00:00 to "
                                               "2026-01-02 23:00:00\\)"):
        write_block_means(source, tmp_path / "out.csv", 120, {"2026-01-02", "2026-01-03"})
    with pytest.raises(MeasurementError, match="no such file"):
        write_block_means(tmp_path / "nope.csv", tmp_path / "out.csv", 15)
    source.write_text("t,T\n2026-01-01T00:00,1\nyesterday,2\n")
    with pytest.raises(MeasurementError, match="line 3: time stamp 'yesterday'"):
        write_block_means(source, tmp_path / "out.csv", 15)


def test_the_command_writes_the_means_and_says_how_many(tmp_path):
    source = _log(tmp_path / "log.csv", range(0, 60))
    result = CliRunner().invoke(app, ["data", "block-means", str(source), "-o", str(tmp_path / "out.csv"),
                                      "--minutes", "30"])
    assert result.exit_code == 0 and "2 blocks of 30 min" in " ".join(result.output.split())
    bad = CliRunner().invoke(app, ["data", "block-means", str(tmp_path / "nope.csv"), "-o", str(tmp_path / "o.csv")])
    assert bad.exit_code == 2 and "no such file" in " ".join(bad.output.split())
