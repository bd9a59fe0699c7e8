"""Calibration end to end on synthetic data: estimates, metrics, results as triples, bad input."""

import matplotlib.image
import numpy as np
import pyoxigraph as ox
import pytest
from case_study import CASE_STUDY, EX, case_study_data, case_study_with_effect

from service.calibration.run import calibrate
from service.components.library import SignatureLibrary
from service.data.windows import parse_window
from service.graph.store import GraphStore
from service.report.calibration_plots import plot_calibration

TRAIN = ("2026-01-12", "2026-01-13T23:59")
TEST = ("2026-01-14", None)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "case.csv"
    store, truth = case_study_data(path, seed=3, n_days=3.0)
    return store, path, truth


@pytest.fixture(scope="module")
def point_run(synthetic):
    store, path, _ = synthetic
    return calibrate(store, "case", path, train=TRAIN, test=TEST, seed=0)


def test_point_calibration_matches_the_truth_within_the_noise(point_run):
    metrics = point_run.record.metrics["test"]
    # measurement noise of the truth: 0.1 K, 0.005 valve, 1 % power
    assert metrics[EX + "coil_outlet_air_temperature_sensor"].rmse < 0.2
    assert metrics[EX + "valve_position_sensor"].rmse < 0.02
    assert metrics[EX + "fan_power_meter"].rmse < 0.03 * metrics[EX + "fan_power_meter"].mean_observed
    assert point_run.record.settings["warmup_s"] == 86400.0  # recorded with the run: its PI loop's day
    assert point_run.record.settings["unscored_start_s"] == 6 * 3600.0  # the training day starts the data
    assert any(w.startswith("the training window's first 6 h are simulated, not scored")
               for w in point_run.record.diagnostics.warnings)


def test_identified_parameters_are_recovered(synthetic, point_run):
    truth = synthetic[2].theta
    recovered = {e.key: e for e in point_run.record.estimates}
    close = [abs(e.median - truth[k]) <= 0.05 * abs(truth[k]) for k, e in recovered.items() if e.identified]
    assert len(close) >= 5 and np.mean(close) >= 0.8
    # the fan's constant term never matters at the flows the data holds: reported, not trusted
    assert not recovered[next(k for k in recovered if k.endswith("#c1"))].identified


def test_results_are_queryable_with_sparql(synthetic, point_run):
    store = synthetic[0]
    rows = store.run_named_query("calibrated-parameters", model="case")
    assert len(rows) == len(point_run.record.estimates)
    by_name = {r["name"].value: r for r in rows}
    assert float(by_name["proportional_gain"]["median"].value) == pytest.approx(
        next(e.median for e in point_run.record.estimates if e.name == "proportional_gain"))
    assert by_name["proportional_gain"]["node"].value == EX + "coil_outlet_air_temperature_controller"
    metrics = store.run_named_query("sensor-metrics", model="case")
    assert {r["window"].value for r in metrics} == {"train", "test"}
    # the test RMSE per operating regime: the regimes' mean squared errors, weighted by their share
    # of the test window, make up the whole window's
    mine = [r for r in metrics if r["run"].value.endswith(point_run.record.run_id) and r["metric"].value == "rmse"
            and r["window"].value == "test"]
    regimes = {r["regime"].value: r for r in mine if "regime" in r}
    assert len(regimes) >= 2 and {r["rule"].value for r in regimes.values()} == {r["rule"] for r in point_run.record.regimes}
    assert sum(float(r["share"].value) for r in regimes.values()) == pytest.approx(1.0)
    for sensor, m in point_run.record.metrics["test"].items():
        parts = [(float(r["share"].value), float(r["value"].value)) for r in mine if "regime" in r and r["sensor"].value == sensor]
        assert sum(s * v**2 for s, v in parts) == pytest.approx(m.rmse**2, rel=0.1), sensor
    # an error of readings in °C is stated in K; no ratio to the mean of an interval scale is written
    air = [r for r in metrics if r["sensor"].value == EX + "coil_outlet_air_temperature_sensor"]
    assert {r["unit"].value for r in air if r["metric"].value in ("rmse", "mae", "noise")} == {"K"}
    assert not {r["metric"].value for r in air} & {"cv_rmse_percent", "nmbe_percent"}
    power = [r for r in metrics if r["sensor"].value == EX + "fan_power_meter" and "regime" not in r]
    assert {r["metric"].value for r in power} >= {"cv_rmse_percent", "nmbe_percent"}
    assert {r["unit"].value for r in power if r["metric"].value == "rmse"} == {"W"}
    history = store.run_named_query("parameter-history", model="case", name="integral_time")
    assert len(history) >= 1 and history[0]["unit"].value == "s"


def test_bad_windows_and_targets_write_nothing(synthetic, tmp_path):
    store, path, _ = synthetic
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match="outside the data"):
        calibrate(store, "case", path, train=("2030-01-01", "2030-01-02"))
    broken = tmp_path / "nan_target.csv"
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    column = header.index("valve_position")
    rows = [",".join("" if i == column else cell for i, cell in enumerate(line.split(","))) for line in lines[1:]]
    broken.write_text("\n".join([lines[0]] + rows))
    with pytest.raises(ValueError, match="valve_position"):
        calibrate(store, "case", broken, train=TRAIN)
    assert set(store.backend.graphs()) == graphs_before
    with pytest.raises(ValueError, match="START/END"):
        parse_window("2026-01-12")
    # shorter than the start it leaves unscored: said so (it read "a target has no measurements" before)
    with pytest.raises(ValueError, match=r"the training window 2026-01-12/2026-01-12T02:00 holds 2.17 h of data, and its "
                                         r"first 6 h are simulated, not scored"):
        calibrate(store, "case", path, train=("2026-01-12", "2026-01-12T02:00"))
    assert set(store.backend.graphs()) == graphs_before


def test_a_refused_diagnosis_says_nothing_of_calibrating_before_it_refuses(synthetic):
    from service.diagnosis.loop import diagnose

    store, path, _ = synthetic
    heard = []
    with pytest.raises(ValueError, match="outside the data"):
        diagnose(store, "case", path, train=("2030-01-01", "2030-01-02"), test=TEST, on_progress=heard.append)
    assert heard == []


def test_a_too_short_test_window_is_refused_before_anything_is_written_and_an_overlap_is_noted(synthetic):
    from service.diagnosis.loop import MIN_TEST_STEPS, diagnose

    store, path, _ = synthetic
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match=f"the test window 2026-01-14T00:00/2026-01-14T00:10 holds 2 steps of data: "
                                         f"at least {MIN_TEST_STEPS} are needed"):
        diagnose(store, "case", path, train=TRAIN, test=("2026-01-14T00:00", "2026-01-14T00:10"))
    assert set(store.backend.graphs()) == graphs_before
    overlapping = calibrate(store, "case", path, train=("2026-01-12", "2026-01-14T11:59"), test=TEST)
    assert any("overlaps the training window by 72 steps" in w for w in overlapping.record.diagnostics.warnings)


def _edited_csv(source, target, column, rows):
    """A copy of the CSV at ``source`` with ``column`` emptied on the data rows ``rows`` (0 = first)."""
    lines = source.read_text().splitlines()
    index = lines[0].split(",").index(column)
    edited = [lines[0]]
    for row, line in enumerate(lines[1:]):
        cells = line.split(",")
        if row in rows:
            cells[index] = ""
        edited.append(",".join(cells))
    target.write_text("\n".join(edited) + "\n")
    return target


def test_a_target_without_measurements_in_the_window_or_file_is_refused(synthetic, tmp_path):
    store, path, _ = synthetic
    graphs_before = set(store.backend.graphs())
    # valve position missing through the whole first day (measured on the other days)
    empty_day = _edited_csv(path, tmp_path / "empty_day.csv", "valve_position", range(144))
    with pytest.raises(ValueError, match="target valve_position_sensor \\(column 'valve_position'\\) has no measurements "
                                         "in the window beyond its warm-up: choose a window"):
        calibrate(store, "case", empty_day, train=("2026-01-12", "2026-01-12T23:59"))
    lines = path.read_text().splitlines()
    drop = lines[0].split(",").index("coil_outlet_water_temperature")
    no_column = tmp_path / "no_column.csv"
    no_column.write_text("\n".join(",".join(c for i, c in enumerate(line.split(",")) if i != drop) for line in lines))
    with pytest.raises(ValueError, match=r"no column for .*coil_outlet_water_temperature_sensor"):
        calibrate(store, "case", no_column, train=TRAIN)
    assert set(store.backend.graphs()) == graphs_before


def test_bounds_that_exclude_a_mapped_value_are_refused_before_anything_is_written(synthetic, tmp_path):
    store, path, _ = synthetic
    text = CASE_STUDY.read_text()
    nominal_power = 'saref:hasValue "1.8"^^xsd:double ;\n    saref:isMeasuredIn unit:KiloW'
    assert nominal_power in text
    store.load_model("case_80kw", text.replace(nominal_power, nominal_power.replace("1.8", "80")).encode())
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match=r"nominal_power of .*supply_fan is mapped from the graph to 80000 W, "
                                         r"outside its bounds \[50, 50000\] W"):
        calibrate(store, "case_80kw", path, train=TRAIN)
    assert set(store.backend.graphs()) == graphs_before


def test_nan_gaps_are_left_out_not_filled(synthetic, tmp_path):
    """A long gap in a target leaves those steps out of that target; a long gap in a boundary input
    leaves them out of every target (the simulator only holds the input there), and the hour after
    it (the model's states catch up); the fit is unharmed. The window starts at the data's first step,
    so its first six hours are not scored either (the PI loop's guessed start state)."""
    store, path, _ = synthetic
    day = range(144)
    target_gap, input_gap = range(40, 60), range(90, 110)  # 20 steps each, beyond the 5-step interpolation
    gappy = _edited_csv(path, tmp_path / "gappy.csv", "valve_position", target_gap)
    gappy = _edited_csv(gappy, gappy, "supply_air_flow", input_gap)
    outcome = calibrate(store, "case", gappy, train=("2026-01-12", "2026-01-12T23:59"), seed=0)
    metrics = outcome.record.metrics["train"]
    unscored, recovery = 36, 6  # the first six hours, and the hour after the input's gap: simulated, not compared
    compared = len(day) - unscored - len(input_gap) - recovery
    assert metrics[EX + "valve_position_sensor"].n == compared - len(target_gap)
    assert metrics[EX + "coil_outlet_air_temperature_sensor"].n == compared
    assert metrics[EX + "fan_power_meter"].rmse < 0.03 * metrics[EX + "fan_power_meter"].mean_observed
    assert metrics[EX + "coil_outlet_air_temperature_sensor"].rmse < 0.2


@pytest.mark.slow  # 70 s on the shared machine (load 12), a point start, 20 steps, 200 predictive draws, 3 figures
def test_a_bayesian_run_with_a_test_window_is_stored_and_plotted(synthetic, tmp_path):
    """End to end through ``calibrate(method="bayes")`` and ``plot_calibration``; a short capped chain
    (the acceptance of the sampler itself is in tests/calibration/test_bayesian_acceptance.py)."""
    store, path, _ = synthetic
    outcome = calibrate(store, "case", path, train=("2026-01-12", "2026-01-12T23:59"),
                        test=("2026-01-13", "2026-01-13T05:59"), method="bayes", seed=1, substeps=1,
                        bayes_settings={"max_steps": 20, "check_interval": 10, "n_temperatures": 2})
    record = outcome.record
    assert record.method == "bayes" and record.diagnostics.sampler.converged is False  # capped: said so
    assert any(w.startswith("the sampler did not converge in 20 steps") for w in record.diagnostics.warnings)
    assert not any(e.identified for e in record.estimates)
    node = EX + "coil_outlet_air_temperature_sensor"
    lower, upper = outcome.intervals["test"][node][0.9]
    median = outcome.predictions["test"][node]
    assert lower.shape == median.shape == (36,) and np.all(lower <= median) and np.all(median <= upper)
    assert {c.level for c in record.metrics["test"][node].coverage} == {0.5, 0.68, 0.9, 0.95, 0.99}
    stored = {(r["metric"].value, float(r["level"].value)): float(r["value"].value)
              for r in store.run_named_query("sensor-metrics", model="case")
              if r["run"].value.endswith(record.run_id) and r["sensor"].value == node and r["window"].value == "test"
              and "level" in r}
    for interval in record.metrics["test"][node].coverage:  # ACE, coverage and width per level, queryable
        assert stored[("ace", interval.level)] == pytest.approx(interval.ace)
        assert stored[("coverage", interval.level)] == pytest.approx(interval.coverage)
        assert stored[("mean_interval_width", interval.level)] == pytest.approx(interval.mean_width)

    paths = plot_calibration(outcome, tmp_path / "plots")
    assert [p.name for p in paths] == [f"{record.run_id}-{kind}.png" for kind in ("fit", "trace", "corner")]
    n_par = len(record.estimates)
    fit, trace, corner = (matplotlib.image.imread(p) for p in paths)
    assert fit.shape[0] == round(2.2 * 5 * 110)  # five sensors, service.report.plots' 2.2 in per panel at 110 dpi
    assert trace.shape[:2] == (round((1.3 * n_par + 0.6) * 90), 9 * 90)  # one panel per parameter
    assert corner.shape[:2] == (round(1.1 * n_par * 90),) * 2
    assert outcome.calibrator.chain_.shape[0] == 20  # the trace shows every step, burn-in included

    # how the sampler ended is stored with the run: a query and the report page tell an unconverged posterior
    from service.report.page import report_html
    from service.report.stored_run import read_run

    sampler = read_run(store, record.run_id).sampler
    assert sampler.converged is False and sampler.n_steps == 20
    assert sampler.acceptance == pytest.approx(record.diagnostics.sampler.acceptance)
    latest = store.run_named_query("calibrated-parameters", model="case")
    assert {r["converged"].value for r in latest if r["run"].value.endswith(record.run_id)} == {"false"}
    page = report_html(store, record.run_id)
    assert "<dt>sampler</dt><dd>NOT converged after 20 steps" in page and "The sampler did not converge" in page
    # the discrepancy GP's posterior per sensor, in physical units: printed, stored, on the page
    gp = record.discrepancy[node]
    assert set(gp) == {"amplitude", "noise", "length_scale:time"}
    assert gp["amplitude"][3] == "K" and gp["noise"][3] == "K" and gp["length_scale:time"][3] == "h"
    assert all(q16 <= median <= q84 for median, q16, q84, _ in gp.values())
    assert read_run(store, record.run_id).discrepancy[node]["amplitude"] == (pytest.approx(gp["amplitude"][0]), "K")
    assert '<table class="discrepancy">' in page and "length scale over time" in page
    assert record.to_dict()["discrepancy"][node]["noise"]["unit"] == "K"


def test_the_discrepancy_runs_over_the_boundary_inputs_the_user_chooses(synthetic):
    """``gp_inputs``: time and the supply air flow (named by its CSV column) are the GP's inputs, one
    length scale each per target, in the training and the test window; recorded with the run."""
    store, path, _ = synthetic
    meter = EX + "supply_air_flow_meter"
    outcome = calibrate(store, "case", path, train=("2026-01-12", "2026-01-12T23:59"),
                        test=("2026-01-13", "2026-01-13T05:59"), method="bayes", seed=1, substeps=1,
                        bayes_settings={"max_steps": 10, "check_interval": 10, "n_temperatures": 2},
                        gp_inputs=["time", "supply_air_flow"])
    assert outcome.record.settings["gp_inputs"] == ["time", meter]
    gp = outcome.record.discrepancy[EX + "coil_outlet_air_temperature_sensor"]
    assert gp["length_scale:supply_air_flow_meter"][3] == "m3/s" and gp["length_scale:time"][3] == "h"
    calibrator = outcome.calibrator
    scales = [n for n in calibrator.hyper_names_ if ":log_length_scale:" in n]
    assert len(scales) == 2 * 5 and sum(n.endswith(":supply_air_flow_meter") for n in scales) == 5
    train = outcome.train
    problem = outcome.model_data.problem(train, gp_inputs=("time", meter))
    np.testing.assert_array_equal(problem.gp_inputs[:, 1], outcome.model_data.data.series[meter][train])
    np.testing.assert_allclose(np.diff(problem.gp_inputs[:, 0]), 600.0 / 3600.0)
    # the Python API takes the names the CLI takes: CSV column, local name, IRI alike
    for name in ("supply_air_flow", "supply_air_flow_meter"):
        np.testing.assert_array_equal(outcome.model_data.problem(train, gp_inputs=("time", name)).gp_inputs, problem.gp_inputs)
    with pytest.raises(ValueError, match="'wind_speed' are no boundary input"):
        outcome.model_data.problem(train, gp_inputs=("wind_speed",))
    assert outcome.intervals["test"][EX + "coil_outlet_air_temperature_sensor"][0.9][0].shape == (36,)


@pytest.mark.parametrize("method, names, problem", [
    ("bayes", ["coil_outlet_air_temperature_sensor"], "no boundary input of the model \\(a target's measurements"),
    ("bayes", ["time", "wind_speed"], "'wind_speed' are no boundary input of the model \\(no device or column"),
    ("point", ["supply_air_flow"], "a point calibration has no discrepancy"),
])
def test_gp_inputs_that_are_no_boundary_input_or_go_to_a_point_fit_are_refused(synthetic, method, names, problem):
    store, path, _ = synthetic
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match=problem) as caught:
        calibrate(store, "case", path, train=TRAIN, method=method, gp_inputs=names)
    if method == "bayes":
        assert ("use time, fan_inlet_air_temperature_sensor, setpoint_schedule, supply_air_flow_meter, "
                "supply_water_temperature_sensor, a node IRI or its CSV column") in str(caught.value)
    assert set(store.backend.graphs()) == graphs_before


def test_a_window_a_gap_covers_is_refused_before_the_fit_naming_the_window_and_the_target(synthetic, tmp_path):
    """A test window whose only readings of a target are missing (a gap longer than is filled) had
    been fitted on and failed afterwards with "no measured step in the window", naming neither."""
    store, path, _ = synthetic
    lines = path.read_text().splitlines()
    column = lines[0].split(",").index("coil_outlet_air_temperature")
    rows = [lines[0]] + [",".join("" if i == column and line.startswith("2026-01-14 1") else cell
                                  for i, cell in enumerate(line.split(","))) for line in lines[1:]]
    gappy = tmp_path / "gappy.csv"
    gappy.write_text("\n".join(rows) + "\n")
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match=r"target coil_outlet_air_temperature_sensor \(column 'coil_outlet_air_temperature'\) "
                                         r"has no measurements in the test window 2026-01-14T11:00 – 2026-01-14T15:00 \(a gap"):
        calibrate(store, "case", gappy, train=TRAIN, test=("2026-01-14T11:00", "2026-01-14T15:00"))
    assert set(store.backend.graphs()) == graphs_before


def test_a_point_run_is_plotted_as_measured_against_predicted_only(point_run, tmp_path):
    (path,) = plot_calibration(point_run, tmp_path)
    assert path.name == f"{point_run.record.run_id}-fit.png"
    assert matplotlib.image.imread(path).shape[0] == round(2.2 * 5 * 110)


def test_the_latest_run_of_each_parameter_is_the_one_queried(point_run):
    """A newer run that estimated only some parameters supersedes the older run for those only."""
    import dataclasses
    from datetime import timedelta

    from service.calibration.run import store_run

    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    older = point_run.record
    newer = dataclasses.replace(older, run_id=older.run_id + "-newer", finished=older.finished + timedelta(hours=1),
                                estimates=[dataclasses.replace(e, median=e.median * 1.5) for e in older.estimates[:3]])
    for record in (newer, older):  # the order written does not matter
        store_run(store, point_run.model, "case", record)
    rows = store.run_named_query("calibrated-parameters", model="case")
    assert len(rows) == len(older.estimates)
    run_of = {(r["component"].value, r["name"].value): r["run"].value.rsplit("/", 1)[-1] for r in rows}
    renewed = {(e.component, e.name) for e in newer.estimates}
    assert run_of == {(e.component, e.name): newer.run_id if (e.component, e.name) in renewed else older.run_id
                      for e in older.estimates}
    # a run ending at the same moment as the newest: still one row per parameter
    twin = dataclasses.replace(newer, run_id=older.run_id + "-twin")
    store_run(store, point_run.model, "case", twin)
    assert len(store.run_named_query("calibrated-parameters", model="case")) == len(older.estimates)
    # a parameter the graph now states (mapped in the current assembly): no stale estimate of it
    stated = older.estimates[-1]
    parameter = ox.NamedNode(f"{stated.component}/parameter/{stated.name}")
    store.backend.update(f"INSERT DATA {{ GRAPH {store.assembly_graph('case')} {{ {parameter} a "
                         f"<https://w3id.org/graphtwin/ontology#MappedParameter> }} }}")
    names = {(r["component"].value, r["name"].value) for r in store.run_named_query("calibrated-parameters", model="case")}
    assert len(names) == len(older.estimates) - 1 and (stated.component, stated.name) not in names


def test_metrics_of_two_sensors_sharing_a_local_name_stay_apart(point_run):
    """Two units' ``…/unit1#sat`` and ``…/unit2#sat``: one metric resource each (before, one resource
    held both sensors' values)."""
    import dataclasses

    from service.calibration.triples import calibration_triples
    from service.graph.namespaces import distinct_local_names
    from service.model.effect_recording import applied_effect_iri

    record = point_run.record
    sensor = EX + "coil_outlet_air_temperature_sensor"
    twin = "https://example.org/unit2#coil_outlet_air_temperature_sensor"
    doubled = dataclasses.replace(record, metrics={w: {**m, twin: m[sensor]} for w, m in record.metrics.items()})
    triples = calibration_triples(doubled, model_graph="urn:g", assembly="urn:a")
    on_sensor = [t for t in triples if t.predicate.value.endswith("#onSensor")]
    per_metric: dict = {}
    for t in on_sensor:
        per_metric.setdefault(t.subject, set()).add(t.object.value)
    assert all(len(sensors) == 1 for sensors in per_metric.values())
    assert {s for sensors in per_metric.values() for s in sensors} >= {sensor, twin}
    library = SignatureLibrary.load()
    assert applied_effect_iri(library["SensorOffset"], sensor) != applied_effect_iri(library["SensorOffset"], twin)
    # the names diagnosis candidates are minted with too: readable where unique, hashed where shared
    names = distinct_local_names([sensor, twin, EX + "fan_power_meter"])
    assert names[EX + "fan_power_meter"] == "fan_power_meter" and names[sensor] != names[twin]
    assert names[sensor].startswith("coil_outlet_air_temperature_sensor-") and len(names[sensor].rsplit("-", 1)[1]) == 8


def test_a_model_that_returns_nan_is_named_with_its_output_and_step(synthetic, monkeypatch):
    """A component giving NaN (an FMU dividing by zero, say) fails every start: the error names the
    component, its signature and model, the output and where it starts, and nothing is written."""
    from service.components.fan import Fan

    store, path, _ = synthetic
    step = Fan.step

    def nan_power(self, params, inputs, state, dt):
        outputs = step(self, params, inputs, state, dt)
        return {**outputs, "electric_power": outputs["electric_power"] * np.nan}

    monkeypatch.setattr(Fan, "step", nan_power)
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match="NaN or infinite") as caught:
        calibrate(store, "case", path, train=TRAIN, seed=0)
    message = str(caught.value)
    assert f"target {EX}fan_power_meter" in message, message
    assert f"it starts at {EX}supply_fan (component " in message, message
    assert "signature Fan, model service.components.fan:Fan): output electric_power is nan from step 0 (2026-01-12T00:00:00)" in message
    assert set(store.backend.graphs()) == graphs_before


def test_a_model_version_starts_from_the_latest_calibration_of_another(point_run):
    """``start_from``: the shared parameters start at the other model's latest calibrated values (keys
    matched without the model name), an added effect's at their defaults; the run records where it
    started."""
    from service.calibration.run import calibrated_start, store_run
    from service.model.assembly import assemble

    store = GraphStore.embedded(None)  # the module's store gets more runs of "case" from other tests
    store.load_model("case", CASE_STUDY)
    store_run(store, point_run.model, "case", point_run.record)
    library = SignatureLibrary.load()
    store.load_model("case_with_heat", case_study_with_effect(library["FanMotorHeat"], EX + "supply_fan"))
    model = assemble(store, "case_with_heat")
    theta, runs, note = calibrated_start(store, "case", "case_with_heat", model)
    base = {e.key.replace("/model/case/", "/model/case_with_heat/"): e.map for e in point_run.record.estimates}
    effect_keys = [r.key for r in model.estimated_parameters if "/FanMotorHeat/" in r.component]
    assert effect_keys and len(base) + len(effect_keys) == len(theta)
    for j, ref in enumerate(model.estimated_parameters):
        assert theta[j] == (ref.spec.default if ref.key in effect_keys else pytest.approx(base[ref.key], rel=1e-12))
    assert [run.rsplit("/", 1)[-1] for run in runs] == [point_run.record.run_id]
    assert f"{len(base)} of {len(theta)} parameters" in note and note.endswith("supply_fan.motor_heat_fraction")
    # which run, on which data: a walkthrough's version had started from a fit to another file, unsaid
    assert note.startswith(f"started from the latest calibration of case ({point_run.record.run_id} on "
                           f"{point_run.record.data_source}): ")


def test_recalibrating_after_an_effect_from_the_base_fit_finds_the_truths_basin(tmp_path):
    """A leaking valve hidden in the truth, six training hours: the model with the leak fitted from the
    component defaults ends in another basin (cost 11.0 against 7.66 at the truth, measured); started
    from the base model's fit, the leak at its default, it reaches the truth's cost."""
    from service.model.wiring import without_model

    library = SignatureLibrary.load()
    data = tmp_path / "leak.csv"
    store, truth = case_study_data(data, library=library, hidden_effect="ValveLeakage", seed=2, n_days=1.0)
    train = ("2026-01-12T06:00", "2026-01-12T11:59")
    calibrate(store, "case", data, train=train, seed=0)
    store.load_model("case+ValveLeakage", case_study_with_effect(library["ValveLeakage"], truth.node))
    after = calibrate(store, "case+ValveLeakage", data, train=train, seed=0, start_from="case")
    problem = after.model_data.problem(after.train)
    at_truth = {without_model(k): v for k, v in truth.theta.items()}
    theta = np.array([at_truth[without_model(r.key)] for r in after.model.estimated_parameters])
    truth_cost = 0.5 * np.sum(problem.weighted_residuals(problem.run(theta[None, :])) ** 2)
    assert after.record.diagnostics.cost <= 1.01 * truth_cost
    defaults = after.record.diagnostics.start.split("at their defaults: ")[1]
    assert defaults == f"{truth.node.rsplit('#', 1)[-1]}.leakage_fraction", defaults  # read as node.name, not a key


def test_a_comparison_of_a_version_starts_its_base_fit_where_told(synthetic, point_run):
    from service.diagnosis.loop import diagnose
    from service.report.stored_run import read_run

    store, path, _ = synthetic
    store.load_model("case_compared", CASE_STUDY)
    report = diagnose(store, "case_compared", path, train=TRAIN, test=TEST, rank_effects=False, start_from="case")
    assert read_run(store, report.run_id).settings["start_from"]["model"] == "case"


def test_a_start_from_nothing_to_start_from_is_refused_and_writes_nothing(synthetic):
    store, path, _ = synthetic
    store.load_model("never_calibrated", CASE_STUDY)
    graphs_before = set(store.backend.graphs())
    with pytest.raises(ValueError, match="'no_such_model': no such model in the store; it holds .*case"):
        calibrate(store, "case", path, train=TRAIN, start_from="no_such_model")
    with pytest.raises(ValueError, match="'never_calibrated': the model has no calibration run"):
        calibrate(store, "case", path, train=TRAIN, start_from="never_calibrated")
    assert set(store.backend.graphs()) == graphs_before


def test_test_inputs_beyond_what_the_training_saw_are_a_note(synthetic):
    """The FLEXLAB heating valve's dead band was fitted just above the training day's highest command;
    the next day's commands above it made a fault-free day look failed, without a word."""
    from service.calibration.model_data import ModelData
    from service.calibration.run import inputs_beyond_training
    from service.data.model_series import read_model_data
    from service.model.assembly import assemble

    store, path, _ = synthetic
    md = ModelData(assemble(store, "case"), read_model_data(assemble(store, "case"), path))
    train, test = md.data.window(*TRAIN), md.data.window(*TEST)
    before = inputs_beyond_training(md, train, test)
    assert not any("supply_air_flow_meter" in n for n in before), before  # the test day's setpoints go higher: said
    flow = md.data.series[EX + "supply_air_flow_meter"]
    seen = float(np.nanmax(flow[train]))
    flow[test.start + 10: test.start + 13] = 1.5 * seen
    [note] = [n for n in inputs_beyond_training(md, train, test) if n not in before]
    assert note.startswith(f"the test window drives supply_air_flow_meter beyond what the training window saw (3 steps, "
                           f"up to {1.5 * seen:.3g} m³/s where training reached {seen:.3g})"), note
    md.data.source_units[EX + "supply_air_flow_meter"] = "http://qudt.org/vocab/unit/L-PER-SEC"  # a column in L/s
    [in_litres] = [n for n in inputs_beyond_training(md, train, test) if "supply_air_flow_meter" in n]
    assert f"up to {1500 * seen:.3g} L/s where training reached {1000 * seen:.3g})" in in_litres, in_litres  # as it reads


def test_a_run_over_a_windows_first_part_is_that_part_run_alone(point_run):
    """The comparison reads a fit window's prediction off the run of the window it starts
    (``service.diagnosis.candidates``): the same warm-up, inputs and states give the same values."""
    md = point_run.model_data
    whole = slice(point_run.train.start, point_run.test.stop)
    part = slice(whole.start, whole.start + (whole.stop - whole.start) // 2)
    lower, upper = md.bounds()
    theta = lower + np.random.default_rng(5).random((3, lower.size)) * (upper - lower)
    long, short = md.simulate_targets(whole, theta), md.simulate_targets(part, theta)
    for node, values in short.items():
        np.testing.assert_array_equal(long[node][:, :values.shape[1]], values, err_msg=node)


def test_a_window_ending_on_a_date_alone_says_it_ends_at_that_days_midnight(tmp_path):
    """``--train 2026-01-12/2026-01-13`` fits 12 January and one step of the 13th: said, with how to
    write the whole day (a user took it for two days)."""
    from service.calibration.run import prepare_calibration

    path = tmp_path / "data.csv"
    store, _ = case_study_data(path, n_days=3, seed=0)
    prepared = prepare_calibration(store, "case", path, train=("2026-01-12", "2026-01-13"), test=("2026-01-13T00:10", None))
    assert prepared.window_notes[0] == ("the training window ends at 2026-01-13T00:00, the first instant of that day "
                                        "(a date alone is its midnight): write 2026-01-13T23:59 to include the day")
    assert prepared.train.stop - prepared.train.start == 24 * 6 + 1
    explicit = prepare_calibration(store, "case", path, train=("2026-01-12", "2026-01-12T23:59"), test=("2026-01-13", None))
    assert not any("a date alone" in note for note in explicit.window_notes)
    # the data stop at 23:50 on the 14th: the 15th as the end is fine, and the note's form would be refused
    to_the_end = prepare_calibration(store, "case", path, train=("2026-01-12", "2026-01-13T23:59"),
                                     test=("2026-01-14", "2026-01-15"))
    assert not any("a date alone" in note for note in to_the_end.window_notes)


def test_a_sensor_the_started_model_fits_worse_than_the_model_it_started_from_is_said(point_run):
    """A leak added to a user's model, calibrated from the model without it: the fan meter's test error
    rose from 14 to 22 W (the fan's unidentified curve drifted) and nothing said so. Compared with the
    start's run on the same data file and test window, the sensor is named with the parameters upstream
    of it that moved furthest; on another data file, or within 25 % of the start's error, nothing is."""
    from dataclasses import replace

    from service.calibration.run import store_run
    from service.calibration.triples import run_iri
    from service.calibration.versus_start import worse_than_start

    store, record, model = GraphStore.embedded(None), point_run.record, point_run.model
    store.load_model("case", CASE_STUDY)
    store_run(store, model, "case", record)
    meter = EX + "fan_power_meter"
    was = record.metrics["test"][meter]
    worse = replace(record, metrics=record.metrics | {"test": record.metrics["test"] | {
        meter: replace(was, rmse=2.0 * was.rmse, noise=0.5 * was.rmse)}})
    start = point_run.theta.copy()
    fan = [j for j, r in enumerate(model.estimated_parameters) if "/supply_fan" in r.component]
    coil = [j for j, r in enumerate(model.estimated_parameters) if "/supply_fan" not in r.component]
    theta = start.copy()
    spans = np.array([r.spec.upper - r.spec.lower for r in model.estimated_parameters])
    theta[fan[0]] += 0.2 * spans[fan[0]]
    theta[coil[0]] += 0.5 * spans[coil[0]]  # moved further, but it cannot reach the meter
    said = worse_than_start(store, [run_iri(record.run_id).value], worse, model, start, theta)
    label = model.estimated_parameters[fan[0]].key.split("/")[-1].replace("#", ".")
    assert len(said) == 1 and said[0].startswith(f"fan_power_meter: test RMSE {2 * was.rmse:.3g} W, against "
                                                 f"{was.rmse:.3g} W in {record.run_id}"), said
    assert f"these moved furthest from that start: {label} (20 % of its range" in said[0]
    assert "heating" not in said[0] and "coil" not in said[0]
    assert worse_than_start(store, [run_iri(record.run_id).value], replace(worse, data_source="other.csv"), model,
                            start, theta) == []
    assert worse_than_start(store, [run_iri(record.run_id).value], record, model, start, theta) == []


def test_a_point_runs_warnings_and_cost_are_stored_with_it(point_run, synthetic):
    """What the run noticed (a window note, a unit mix-up) was said in the terminal and lost: each
    warning is a gt:runWarning of the run, its cost a gt:leastSquaresCost; a point fit has no sampler."""
    from service.calibration.triples import run_iri
    from service.report.stored_run import read_run

    store, _, _ = synthetic
    record = point_run.record
    stored = read_run(store, record.run_id)
    assert record.diagnostics.warnings and stored.warnings == sorted(record.diagnostics.warnings)
    assert stored.sampler is None
    cost = store.query("PREFIX gt: <https://w3id.org/graphtwin/ontology#> "
                       "SELECT ?c WHERE { GRAPH ?g { ?run gt:leastSquaresCost ?c } }",
                       substitutions={"run": run_iri(record.run_id)})
    assert float(cost[0]["c"].value) == pytest.approx(record.diagnostics.cost)


def test_a_bayesian_runs_identifiability_is_the_posteriors():
    """A Bayesian run showed the point fit's verdict (its Jacobian's 95 % interval of ±5.9e+08 s) beside a
    posterior of 11–40 s: the verdict is now the posterior's, identified where its 16–84 % interval is
    under half its uniform prior's."""
    from types import SimpleNamespace

    from service.calibration.bayesian import posterior_identifiability

    problem = SimpleNamespace(parameter_names=("pinned", "loose"), lower=np.array([0.0, 5.0]),
                              upper=np.array([1.0, 300.0]))
    verdicts = posterior_identifiability(problem, np.array([0.40, 11.0]), np.array([0.50, 250.0]))
    assert verdicts["pinned"].identified and verdicts["pinned"].reasons == ()
    assert not verdicts["loose"].identified
    assert verdicts["loose"].reasons[0].startswith("its posterior 16–84 % interval spans 119 % of its prior's")
    # an unconverged run's draws are no posterior: nothing is called identified (a helper's 300-step run
    # called a supply water temperature of 42 [37.5–48.4] °C identified, the truth 71 °C)
    unconverged = posterior_identifiability(problem, np.array([0.40, 11.0]), np.array([0.50, 250.0]), converged=False)
    assert not any(v.identified for v in unconverged.values())
    assert unconverged["pinned"].reasons == ("the sampler did not converge: its draws are no posterior to judge by",)
