"""A column in another unit than the model declares is named at the comparison, with the unit it is
probably in: the controlled air temperature, or the coil's outlet water, written in °F under the
case study's °C (the calibration bends the water side towards the misread outlet water; the
model at its parameters' defaults shows it). The same data as generated raise no such warning. A
meter the model has a free curve for can hide it: the fan's power in kW under its W is fitted by the
curve, and the meter does not fail."""

import pytest
from case_study import case_study_data

from service.diagnosis.loop import diagnose

TRAIN, TEST = ("2026-01-12", "2026-01-12T23:59"), ("2026-01-13", None)


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    path = tmp_path_factory.mktemp("mixup") / "data.csv"
    store, _ = case_study_data(path, seed=4, n_days=2.0)
    return store, path


def _rewritten(path, target, column, convert):
    lines = path.read_text().splitlines()
    index = lines[0].split(",").index(column)
    rows = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[index] = f"{convert(float(cells[index])):.4f}" if cells[index] else ""
        rows.append(",".join(cells))
    target.write_text("\n".join(rows) + "\n")
    return target


def _warnings(store, path):
    report = diagnose(store, "case", path, train=TRAIN, test=TEST, seed=0, rank_effects=False)
    return [w for w in report.data_warnings if "the model declares" in w]


@pytest.mark.parametrize(("column", "convert", "unit"), [
    ("coil_outlet_air_temperature", lambda c: 32.0 + 1.8 * c, "°F"),
    ("coil_outlet_water_temperature", lambda c: 32.0 + 1.8 * c, "°F"),
])
def test_a_column_in_another_unit_is_named_with_the_unit_it_reads_right_in(generated, tmp_path, column, convert, unit):
    store, path = generated
    warnings = _warnings(store, _rewritten(path, tmp_path / "mixed.csv", column, convert))
    assert len(warnings) == 1 and warnings[0].startswith(f"column {column!r}"), warnings
    assert f"is it in {unit}?" in warnings[0], warnings


def test_a_calibration_alone_warns_of_the_column_too(generated, tmp_path):
    """Found by the calibration (its last window, here the training one), not only by a diagnosis: a
    user who only calibrates had a 46 K misfit and no word of the unit."""
    from service.calibration.run import calibrate

    store, path = generated
    mixed = _rewritten(path, tmp_path / "mixed.csv", "coil_outlet_air_temperature", lambda c: 32.0 + 1.8 * c)
    outcome = calibrate(store, "case", mixed, train=TRAIN, seed=0)
    said = [w for w in outcome.record.diagnostics.warnings if "the model declares" in w]
    assert len(said) == 1 and said[0].startswith("column 'coil_outlet_air_temperature'") and "is it in °F?" in said[0]


def test_a_boundary_flow_in_another_unit_is_named_by_the_graphs_nominal_flow(generated, tmp_path):
    """The supply air flow in m³/h under a model that says m³/s drives the model with 3,600 times the
    flow; no prediction can meet a boundary input, so its scale is judged by the fan's nominal flow."""
    from service.calibration.run import calibrate

    store, path = generated
    mixed = _rewritten(path, tmp_path / "flow.csv", "supply_air_flow", lambda q: 3600.0 * q)
    outcome = calibrate(store, "case", mixed, train=TRAIN, seed=0)
    said = [w for w in outcome.record.diagnostics.warnings if "the graph states" in w]
    assert len(said) == 1 and said[0].startswith("column 'supply_air_flow'"), said
    assert "times the nominal_air_flow of supply_fan the graph states (1.5 m³/s): is it in m³/h?" in said[0]
    assert not [w for w in calibrate(store, "case", path, train=TRAIN, seed=0).record.diagnostics.warnings
                if "the graph states" in w]


@pytest.mark.parametrize(("column", "convert", "unit"), [
    ("fan_inlet_air_temperature", lambda c: 32.0 + 1.8 * c, "°F"),
    ("supply_water_temperature", lambda c: c + 273.15, "K"),
])
def test_a_boundary_temperature_in_another_unit_is_named_by_how_much_closer_the_targets_come(
        generated, tmp_path, column, convert, unit):
    """Outdoor air in °F under a model that says °C drove the model with air at 30–60 °C: every target
    missed by tens of kelvin and nothing was said. The graph gives no scale for a temperature (air or
    water, set point or reading), so the model at its defaults is run with the column read in each
    other unit: the one that brings the targets far closer is named."""
    from service.calibration.run import calibrate

    store, path = generated
    mixed = _rewritten(path, tmp_path / "input.csv", column, convert)
    said = [w for w in calibrate(store, "case", mixed, train=TRAIN, test=TEST, seed=0).record.diagnostics.warnings
            if "the model declares" in w]
    assert len(said) == 1 and said[0].startswith(f"column {column!r}") and "a boundary input" in said[0], said
    assert f"is it in {unit}?" in said[0]


def test_the_data_as_generated_raise_no_unit_warning(generated):
    store, path = generated
    assert _warnings(store, path) == []


def test_readings_shrunk_towards_a_prediction_near_zero_are_not_a_unit_mixup():
    """A flow of 0.4 m³/s the model predicts as off: read in L/min it is 0.0067 m³/s, 60 times nearer
    the prediction of zero without meeting anything (the reviewer's case); read in °F, a °C series
    that meets its prediction is named."""
    from types import SimpleNamespace

    import numpy as np

    from service.calibration.unit_mixup import unit_mixups

    u = "http://qudt.org/vocab/unit/"
    rng = np.random.default_rng(0)
    flow, temperature = 0.4 + 0.01 * rng.normal(size=200), 20.0 + np.sin(np.arange(200) / 20.0)
    data = SimpleNamespace(source_units={"flow": u + "M3-PER-SEC", "air": u + "DEG_C"},
                           columns={"flow": "SA flow", "air": "DAT"})
    observed = {"flow": flow, "air": 32.0 + 1.8 * temperature}  # the air column is in °F
    predicted = {"flow": np.zeros(200), "air": temperature}
    warnings = unit_mixups(data, {"flow": "m3/s", "air": "degC"}, observed, [predicted])
    assert len(warnings) == 1 and warnings[0].startswith("column 'DAT' (air): read as °F"), warnings
