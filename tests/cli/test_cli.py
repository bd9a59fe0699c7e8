"""The command line: JSON output, clear errors with exit code 2, add-effect round trip."""

import csv
import gc
import io
import json
import re
import shlex
import subprocess
import sys

import pyoxigraph as ox
import pytest
from case_study import CASE_STUDY, EX
from store_holder import held_by_another_process
from typer.testing import CliRunner

from service.cli import app
from service.components.library import SignatureLibrary
from service.graph.store import GraphStore
from service.matching.compiler import compile_signature
from service.model.assembly import assemble

runner = CliRunner()


def test_assemble_prints_the_model_as_json():
    result = runner.invoke(app, ["assemble", str(CASE_STUDY), "--memory", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert len(data["targets"]) == 5 and len(data["boundary_inputs"]) == 4
    assert len(data["parameters"]["estimated"]) == 17


def test_assemble_prints_tables_a_terminal_of_80_columns_can_read(monkeypatch):
    """Local names (the namespace said once) and unit labels: full IRIs were cut to "https://example.o…"."""
    monkeypatch.setenv("COLUMNS", "80")
    result = runner.invoke(app, ["assemble", str(CASE_STUDY), "--memory"])
    assert result.exit_code == 0, result.output
    assert f"nodes in {EX}" in result.output and "https://example.o…" not in result.output
    assert "coil_outlet_air_temperature_se" in result.output and "°C" in result.output  # names fold, not cut
    assert "HotWaterLoop/heating_" in result.output and "Fan/supply_fan" in result.output  # signature/node
    assert "…" not in result.output
    # a value the graph states is "mapped", one the model sets from what is measured "fixed"
    flat = " ".join(result.output.split())
    assert "3 mapped, 1 fixed by what is or is not measured and 17 estimated parameters" in flat
    assert "impeller_heat_share" in result.output and "fixed 0.3" in flat


def test_a_broken_model_fails_with_line_and_column(tmp_path):
    broken = tmp_path / "broken.ttl"
    broken.write_text("@prefix ex: <https://example.org/x#> .\nex:a ex:b ex:c .\nex:d zz:e ex:f .\n")
    result = runner.invoke(app, ["assemble", str(broken), "--memory"])
    assert result.exit_code == 2
    assert "line 3" in result.output and "zz:" in result.output


def test_an_incomplete_models_misspellings_are_said_with_their_line_and_column_in_the_file(tmp_path):
    """A misspelt class that leaves the fan unmodelled (a problem) and a misspelt property (a note):
    each sentence ends with where the file first uses the term, as the store keeps no positions."""
    text = CASE_STUDY.read_text(encoding="utf-8")
    feeds = "fso:suppliesFluidTo ex:coil_outlet_air_temperature_sensor"
    typo = tmp_path / "typo.ttl"
    typo.write_text(text.replace("ex:supply_fan a s4bldg:Fan", "ex:supply_fan a s4bldg:Fam")
                    .replace(feeds, feeds.replace("FluidTo", "FluidToo")), encoding="utf-8")
    lines = typo.read_text(encoding="utf-8").splitlines()
    fan_line = next(i for i, line in enumerate(lines, 1) if "s4bldg:Fam" in line)
    feeds_line = next(i for i, line in enumerate(lines, 1) if "fso:suppliesFluidToo" in line)
    result = runner.invoke(app, ["assemble", str(typo), "--memory"], env={"COLUMNS": "400"})
    assert result.exit_code == 2
    flat = " ".join(result.output.split())
    fan_column = lines[fan_line - 1].index("s4bldg:Fam") + 1
    feeds_column = lines[feeds_line - 1].index("fso:suppliesFluidToo") + 1
    assert f"(did you mean https://saref.etsi.org/saref4bldg/Fan?) (typo.ttl, line {fan_line}, column {fan_column})" in flat
    assert f"(typo.ttl, line {feeds_line}, column {feeds_column})" in flat and "suppliesFluidToo" in flat
    # a model that assembles with a misspelt property: its note says where, as the assembly's table shows it
    typo.write_text(text.replace(feeds, feeds.replace("FluidTo", "FluidToo")), encoding="utf-8")
    result = runner.invoke(app, ["assemble", str(typo), "--memory"], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    assert f"(typo.ttl, line {feeds_line}, column {feeds_column})" in " ".join(result.output.split())


@pytest.mark.parametrize("command", ["calibrate", "assemble"])
def test_a_command_that_fails_leaves_the_stored_model_as_it_was(tmp_path, command):
    """The same model name, a changed file, and a command that fails after loading it (measurements
    without the model's columns; a model the library matches nowhere): the store keeps the model and
    its assembly as the last successful command left them."""
    store = tmp_path / "store"
    assert _run(["assemble", str(CASE_STUDY), "--name", "m", "--store", str(store)])[0] == 0
    queries = ("assembled-components", "flow-edges")
    before = {q: _run(["query", q, "--model", "m", "--store", str(store)])[1] for q in queries}
    if command == "calibrate":
        changed = tmp_path / "changed.ttl"
        changed.write_text(CASE_STUDY.read_text().replace("supply_fan", "supply_fan_x"))
        data = tmp_path / "data.csv"
        data.write_text("timestamp,a\n2026-01-01T00:00,1\n2026-01-01T00:10,2\n")
        args = ["calibrate", str(changed), str(data)]
    else:
        changed = tmp_path / "nothing.ttl"
        changed.write_text("<https://example.org/a> <https://example.org/b> <https://example.org/c> .\n")
        args = ["assemble", str(changed)]
    code, output = _run([*args, "--name", "m", "--store", str(store)])
    assert code == 2, output
    after = {q: _run(["query", q, "--model", "m", "--store", str(store)])[1] for q in queries}
    assert after == before and "supply_fan_x" not in after["flow-edges"] and before["assembled-components"].count("\n") > 10


def test_signature_explain_prints_the_compiled_query():
    result = runner.invoke(app, ["signature", "explain", "Fan"])
    assert result.exit_code == 0 and "suppliesFluidTo+" in result.output
    # piped: the text as it is (no wrapping of long comment lines), a query any endpoint parses
    assert result.output == compile_signature(SignatureLibrary.load()["Fan"]).text
    assert list(ox.Store().query(result.output)) == []
    assert runner.invoke(app, ["signature", "explain", "Fann"]).exit_code == 2


def test_add_effect_records_triples_that_reassembly_picks_up(tmp_path):
    output = tmp_path / "with_effect.ttl"
    result = runner.invoke(app, ["add-effect", str(CASE_STUDY), "--effect", "ValveLeakage",
                                 "--target", EX + "heating_valve", "-o", str(output)])
    assert result.exit_code == 0, result.output
    text = output.read_text()
    assert text.startswith(CASE_STUDY.read_text().rstrip("\n")) and "hasEffect" in text
    store = GraphStore.embedded(None)
    store.load_model("v2", output)
    model = assemble(store, "v2")
    assert any(c.signature.id == "ValveLeakage" for c in model.components.values())


@pytest.mark.parametrize("suffix", [".jsonld", ".rdf", ".nt"])
def test_add_effect_writes_the_format_its_output_names_and_refuses_the_same_effect_twice(tmp_path, suffix):
    output = tmp_path / f"with_effect{suffix}"
    result = runner.invoke(app, ["add-effect", str(CASE_STUDY), "--effect", "ValveLeakage",
                                 "--target", EX + "heating_valve", "-o", str(output)])
    assert result.exit_code == 0, result.output
    store = GraphStore.embedded(None)
    store.load_model("v2", output)  # parsed as its suffix says
    assert any(c.signature.id == "ValveLeakage" for c in assemble(store, "v2").components.values())
    again = runner.invoke(app, ["add-effect", str(output), "--effect", "ValveLeakage",
                                "--target", EX + "heating_valve", "-o", str(tmp_path / f"twice{suffix}")])
    assert again.exit_code == 2 and "is recorded at" in again.output and "already" in again.output
    assert not (tmp_path / f"twice{suffix}").exists()
    unknown = runner.invoke(app, ["add-effect", str(output), "--effect", "FanMotorHeat",
                                  "--target", EX + "supply_fan", "-o", str(tmp_path / "v3.txt")])
    assert unknown.exit_code == 2 and "v3.txt" in unknown.output and "unsupported RDF format" in unknown.output


def test_add_effect_says_a_drift_is_a_parameter_that_changed_not_an_effect_to_add(tmp_path):
    result = runner.invoke(app, ["add-effect", str(CASE_STUDY), "--effect", "LinearDrift/water_side_conductance",
                                 "--target", EX + "heating_coil_air_side", "-o", str(tmp_path / "x.ttl")])
    assert result.exit_code == 2 and not (tmp_path / "x.ttl").exists()
    assert "parameter water_side_conductance changed during the test window" in " ".join(result.output.split())
    assert "calibrate again on data from after the change" in " ".join(result.output.split())


def test_add_effect_refuses_an_effect_that_does_not_apply(tmp_path):
    result = runner.invoke(app, ["add-effect", str(CASE_STUDY), "--effect", "FanMotorHeat",
                                 "--target", EX + "heating_valve", "-o", str(tmp_path / "x.ttl")])
    assert result.exit_code == 2 and "does not apply" in result.output
    result = runner.invoke(app, ["add-effect", str(CASE_STUDY), "--effect", "Nope", "--target", EX + "x",
                                 "-o", str(tmp_path / "x.ttl")])
    assert result.exit_code == 2 and "FanMotorHeat" in result.output


def test_example_generate_writes_the_columns_the_model_needs(tmp_path):
    output = tmp_path / "data.csv"
    truth = tmp_path / "truth.json"
    result = runner.invoke(app, ["example", "generate", "ventilation_case_study", "--hidden-effect", "SensorOffset",
                                 "--days", "1", "-o", str(output), "--truth-json", str(truth)])
    assert result.exit_code == 0, result.output
    written = json.loads(truth.read_text())
    assert written["hidden_effect"] == "SensorOffset" and written["node"].startswith(EX)
    assert any(key.endswith("#offset") for key in written["parameters"]) and len(written["parameters"]) > 14
    again = tmp_path / "again.json"  # read back, it is the truth again (the noise is drawn anew)
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--hidden-effect", "SensorOffset", "--days",
                               "1", "-o", str(tmp_path / "again.csv"), "--truth-from", str(truth), "--truth-json", str(again)]).exit_code == 0
    assert json.loads(again.read_text()) == written
    header = output.read_text().splitlines()[0].split(",")
    assert header[0] == "time" and "coil_outlet_air_temperature" in header and len(header) == 10
    assert len(output.read_text().splitlines()) == 1 + 144
    bad = runner.invoke(app, ["example", "generate", "ventilation_case_study", "--hidden-effect", "Nope", "-o", str(output)])
    assert bad.exit_code == 2 and "CoilThermalMass" in bad.output


def test_example_generate_drives_a_given_truth_with_a_measured_operation(tmp_path):
    """Semi-synthetic data: the boundary columns and time grid of a measured file, the targets from a
    truth whose parameters come from a calibration's JSON (keys of the model under another name)."""
    operation = tmp_path / "operation.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "1", "--seed", "3",
                               "-o", str(operation)]).exit_code == 0
    key = "https://w3id.org/graphtwin/resource/model/elsewhere/component/PIController/coil_outlet_air_temperature_controller#proportional_gain"
    columns = {}
    for gain in (0.004, 0.04):
        run = tmp_path / f"run-{gain}.json"
        run.write_text(json.dumps({"parameters": {key: {"median": gain, "quantile16": 0.0}}}))
        output = tmp_path / f"semi-{gain}.csv"
        result = runner.invoke(app, ["example", "generate", str(CASE_STUDY), "--operation", str(operation),
                                     "--truth-from", str(run), "--hidden-effect", "FanMotorHeat", "-o", str(output)])
        assert result.exit_code == 0, result.output
        assert "1 parameters from" in result.output and "FanMotorHeat" in result.output
        header, *rows = [line.split(",") for line in output.read_text().splitlines()]
        columns[gain] = dict(zip(header, zip(*rows)))
    measured_header, *measured_rows = [line.split(",") for line in operation.read_text().splitlines()]
    measured = dict(zip(measured_header, zip(*measured_rows)))
    for name in ("time", "supply_air_flow", "coil_outlet_air_temperature_setpoint", "fan_inlet_air_temperature",
                 "supply_water_temperature"):
        assert columns[0.004][name] == columns[0.04][name] == measured[name], name  # the measured operation
    assert columns[0.004]["valve_position"] != columns[0.04]["valve_position"]  # the given gain drives the loop
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"parameters": {key.replace("proportional_gain", "proportional_gian"): {"median": 1.0}}}))
    result = runner.invoke(app, ["example", "generate", str(CASE_STUDY), "--truth-from", str(bad), "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "proportional_gian" in result.output
    bad.write_text("{}")
    result = runner.invoke(app, ["example", "generate", str(CASE_STUDY), "--truth-from", str(bad), "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "calibrate --json" in result.output


def test_example_generate_for_a_model_the_built_in_operation_cannot_drive_names_the_operation_option(tmp_path):
    result = runner.invoke(app, ["example", "generate", "flexlab_ahu", "--days", "1", "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "--operation FILE" in result.output, result.output


def test_simulate_writes_simulation_beside_measurements(tmp_path):
    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "1", "-o", str(data)]).exit_code == 0
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"proportional_gain": 0.02}))
    out = tmp_path / "out.csv"
    result = runner.invoke(app, ["simulate", str(CASE_STUDY), str(data), "--params", str(params), "-o", str(out), "--memory"])
    assert result.exit_code == 0, result.output
    header = out.read_text().splitlines()[0].split(",")
    assert "coil_outlet_air_temperature (simulated)" in header
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"proportional_gian": 0.02}))
    result = runner.invoke(app, ["simulate", str(CASE_STUDY), str(data), "--params", str(bad), "--memory"])
    assert result.exit_code == 2 and "proportional_gian" in result.output


def test_compare_locates_a_hidden_leak_without_testing_the_catalog_and_saves_its_plots(tmp_path):
    from matplotlib.image import imread

    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--hidden-effect", "ValveLeakage",
                               "--days", "2", "--seed", "2", "-o", str(data)]).exit_code == 0
    window = ["--train", "2026-01-12/2026-01-12T23:59", "--test", "2026-01-13/"]
    result = runner.invoke(app, ["compare", str(CASE_STUDY), str(data), *window, "--memory", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["effects"] == [] and report["effects_tested"] is False
    assert report["nothing_significant_missing"] is None  # not asked, so not answered
    failing = {node for node, sensor in report["sensors"].items() if sensor["fails"]}
    disturbed = {EX + name for name in ("coil_inlet_water_temperature_sensor", "coil_outlet_air_temperature_sensor",
                                        "coil_outlet_water_temperature_sensor")}  # the water the leak passes heats
    assert failing and failing <= disturbed, report["sensors"]
    assert any(EX + "heating_valve" in loc["components"] for loc in report["localization"]), report["localization"]
    assert set(report["residual_dependence"]) == failing  # pointers for every failing sensor
    plots = tmp_path / "plots"
    text = runner.invoke(app, ["compare", str(CASE_STUDY), str(data), *window, "--memory", "--plots", str(plots)])
    assert text.exit_code == 0, text.output
    assert "fails" in text.output and "Which effect is missing" not in text.output
    pngs = sorted(plots.glob("*.png"))
    assert [p.name.rsplit("-", 1)[1] for p in pngs] == ["residuals.png", "test.png"]
    assert all(imread(p).shape[0] > 200 for p in pngs)


def test_diagnose_prints_the_command_that_adds_its_answer_and_that_command_works(tmp_path, monkeypatch):
    """The answer's next step as one line to copy: run as printed, it writes the model with the effect."""
    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--hidden-effect", "ValveLeakage",
                               "--days", "2", "--seed", "2", "-o", str(data)]).exit_code == 0
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["diagnose", str(CASE_STUDY), str(data), "--train", "2026-01-12/2026-01-12T23:59",
                                 "--test", "2026-01-13/", "--memory", "--plots", str(tmp_path / "plots")])
    assert result.exit_code == 0, result.output
    rows = [t.split("│") for t in result.output.splitlines() if t.startswith("│ ")]
    nmbe = {row[1].strip(): row[4].strip() for row in rows if len(row) > 5 and row[4].strip()}
    nmbe = {next(n for n in ("coil_outlet_air", "fan_power") if name.startswith(n)): ratio  # names fold to the width
            for name, ratio in nmbe.items() if name.startswith(("coil_outlet_air", "fan_power"))}
    assert nmbe["coil_outlet_air"] == "–" and nmbe["fan_power"] != "–", nmbe  # a mean in °C has no ratio
    line = next(t for t in result.output.splitlines() if t.startswith("add it to the model: "))
    assert "it appeared in the test window" not in result.output  # the hidden leak is there from the start
    command = line.removeprefix("add it to the model: ")
    assert shlex.split(command) == ["graphtwin", "add-effect", str(CASE_STUDY), "--effect", "ValveLeakage", "--target",
                                    f"{EX}heating_valve", "-o", "model+ValveLeakage.ttl"]
    added = runner.invoke(app, shlex.split(command)[1:])
    assert added.exit_code == 0, added.output
    assert "ValveLeakage" in (tmp_path / "model+ValveLeakage.ttl").read_text()


def test_data_check_reads_a_file_as_the_model_needs_it_and_names_what_is_wrong(tmp_path):
    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "1", "-o", str(data)]).exit_code == 0
    wide = CliRunner(env={"COLUMNS": "200"})
    result = wide.invoke(app, ["data", "check", str(CASE_STUDY), str(data), "--memory"])
    assert result.exit_code == 0, result.output
    rows = {line.split("│")[1].strip(): [c.strip() for c in line.split("│")[2:-1]]
            for line in result.output.splitlines() if line.startswith("│")}
    assert rows["fan_power_meter"][:4] == ["target", "supply_fan_power", "W → W", "144 of 144"], rows
    assert rows["supply_water_temperature_sensor"][0] == "boundary input"
    header, *lines = data.read_text().splitlines()
    data.write_text("\n".join([header.replace("supply_fan_power", "supply_fan_pwr"), *lines]) + "\n")
    broken = wide.invoke(app, ["data", "check", str(CASE_STUDY), str(data), "--memory"])
    assert broken.exit_code == 2 and "no column for https://example.org/ventilation-case-study#fan_power_meter" in broken.output
    column = header.split(",").index("supply_fan_power")  # a target whose column holds no number: calibrate refuses it
    data.write_text("\n".join([header, *(",".join("" if i == column else c for i, c in enumerate(line.split(",")))
                                          for line in lines)]) + "\n")
    empty = wide.invoke(app, ["data", "check", str(CASE_STUDY), str(data), "--memory"])
    assert empty.exit_code == 2 and "column 'supply_fan_power' (fan_power_meter, target) holds no number" in empty.output


def test_compare_strategies_prints_both_fits_per_regime_and_their_cross_validation(tmp_path):
    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "1", "--seed", "1",
                               "-o", str(data)]).exit_code == 0
    result = runner.invoke(app, ["compare-strategies", str(CASE_STUDY), str(data), "--folds", "2", "--memory", "--json"])
    assert result.exit_code == 0, result.output
    comparison = json.loads(result.output)
    assert set(comparison["strategies"]) == {"joint", "successive"} and comparison["better"] in (
        "joint", "successive", "tie")
    assert all(len(s["cv"]) == 2 for s in comparison["strategies"].values())
    assert comparison["plan"] and comparison["rules"]
    text = runner.invoke(app, ["compare-strategies", str(CASE_STUDY), str(data), "--folds", "2", "--memory"])
    assert text.exit_code == 0 and "better on held-out data:" in text.output and "joint | successive" in text.output
    short = runner.invoke(app, ["compare-strategies", str(CASE_STUDY), str(data), "--folds", "30", "--memory"])
    assert short.exit_code == 2 and "30 folds" in short.output


def test_a_store_another_process_holds_is_a_one_line_error(tmp_path):
    path = tmp_path / "data"
    with held_by_another_process(path):
        result = runner.invoke(app, ["assemble", str(CASE_STUDY), "--store", str(path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"error: store {path} is in use by another process (another graphtwin command, or a running graphtwin serve" in result.output


def test_add_effect_with_a_local_name_suggests_the_full_iri(tmp_path):
    result = runner.invoke(app, ["add-effect", str(CASE_STUDY), "--effect", "FanMotorHeat", "--target", "supply_fan",
                                 "-o", str(tmp_path / "x.ttl")])
    assert result.exit_code == 2
    assert f"the model has no node supply_fan: give its full IRI, e.g. {EX}supply_fan" in result.output


def test_a_model_ttl_in_the_current_folder_is_model_named_model(tmp_path, monkeypatch):
    (tmp_path / "model.ttl").write_bytes(CASE_STUDY.read_bytes())
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["assemble", "model.ttl", "--store", str(tmp_path / "store")])
    assert result.exit_code == 0, result.output
    assert GraphStore.embedded(tmp_path / "store").models() == ["model"]


def _run(args: list[str]) -> tuple[int, str]:
    """Exit code and output of a command that opens the on-disk store; its store is closed after
    (the runner keeps the command's frames, which hold it, in the result: a process would exit)."""
    result = runner.invoke(app, args)
    outcome = (result.exit_code, result.output)
    del result
    gc.collect()
    return outcome


def test_a_query_table_shows_floating_point_numbers_to_six_digits_and_iris_by_name():
    from service.cli.store_commands import _table_cell

    xsd = "http://www.w3.org/2001/XMLSchema#"
    assert _table_cell(ox.Literal("1862.4781253881902", datatype=ox.NamedNode(xsd + "double"))) == "1862.48"
    assert _table_cell(ox.Literal("3.328998501128e-11", datatype=ox.NamedNode(xsd + "double"))) == "3.329e-11"
    assert _table_cell(ox.Literal("0.12345678", datatype=ox.NamedNode(xsd + "decimal"))) == "0.123457"
    assert _table_cell(ox.Literal("123456789", datatype=ox.NamedNode(xsd + "integer"))) == "123456789"
    assert _table_cell(ox.Literal("2026-01-15T00:00:00")) == "2026-01-15T00:00:00"
    assert _table_cell(ox.NamedNode(EX + "supply_fan")) == "supply_fan"
    # a run's results repeat their local names from run to run ("diagnosis" on every row): the run says which
    run = "https://w3id.org/graphtwin/resource/run/case-point-1a2b3c4d"
    assert _table_cell(ox.NamedNode(run + "/diagnosis")) == "case-point-1a2b3c4d/diagnosis"
    assert _table_cell(ox.NamedNode(run)) == "case-point-1a2b3c4d"


def test_query_prints_csv_or_json_with_full_iris_and_refuses_an_unknown_model(tmp_path):
    store = ["--store", str(tmp_path / "store")]
    assert _run(["assemble", str(CASE_STUDY), *store])[0] == 0
    coil = ["--param", "class=https://saref.etsi.org/saref4bldg/Coil"]
    code, output = _run(["query", "models-for-class", *coil, *store])  # piped: CSV
    assert code == 0, output
    rows = list(csv.DictReader(io.StringIO(output)))
    assert {r["id"] for r in rows} >= {"HotWaterLoop", "WaterCoil"}
    assert all(r["signature"].startswith("https://w3id.org/graphtwin/resource/signature/") for r in rows)
    code, output = _run(["query", "models-for-class", *coil, "--format", "json", *store])
    assert [r["id"] for r in json.loads(output)] == [r["id"] for r in rows]
    code, output = _run(["query", "calibrated-parameters", "--model", "modle", *store])
    assert code == 2 and "no model 'modle' in the store" in output and "ventilation_case_study" in output
    code, output = _run(["query", "calibrated-paramters", *store])
    assert code == 2 and "error: no query 'calibrated-paramters'" in output
    # a query about a building graph runs over the model's graphs (it printed no rows before)
    code, output = _run(["query", "flow-edges", "--model", "ventilation_case_study", *store])
    edges = {(r["from"].removeprefix(EX), r["to"].removeprefix(EX), r["kind"]) for r in csv.DictReader(io.StringIO(output))}
    assert code == 0 and ("heating_coil_water_side", "heating_coil_air_side", "heat") in edges and len(edges) > 10
    code, output = _run(["query", "measurement-link", "--model", "ventilation_case_study", "--param",
                         f"device={EX}fan_power_meter", *store])
    assert code == 0 and "supply_fan_power,http://qudt.org/vocab/unit/W" in output
    code, output = _run(["query", "flow-edges", *store])
    assert code == 2 and "query flow-edges reads a building model's graphs: give --model" in output


def test_query_runs_a_select_query_of_ones_own_and_names_the_file_of_a_bad_one(tmp_path):
    store = ["--store", str(tmp_path / "store")]
    assert _run(["assemble", str(CASE_STUDY), *store])[0] == 0
    fans = tmp_path / "fans.rq"
    fans.write_text("PREFIX s4bldg: <https://saref.etsi.org/saref4bldg/>\n"
                    "SELECT ?fan WHERE { ?fan a s4bldg:Fan }\n")
    code, output = _run(["query", str(fans), "--model", "ventilation_case_study", *store])
    assert code == 0 and [r["fan"] for r in csv.DictReader(io.StringIO(output))] == [EX + "supply_fan"], output
    broken = tmp_path / "broken.rq"
    broken.write_text("SELECT ?x WHERE { ?x ?p }")
    code, output = _run(["query", str(broken), "--model", "ventilation_case_study", *store])
    assert code == 2 and f"{broken}: SPARQL syntax error at line 1, column " in output.replace("\n", "")
    broken.write_text("SELECT ?run WHERE {\n  ?run prov:used ?data }")  # no PREFIX prov:
    code, output = _run(["query", str(broken), "--model", "ventilation_case_study", *store])
    assert code == 2 and ("SPARQL syntax error at line 2, column 17: '?run prov:used ?data }': the prefix prov: is not "
                          "declared (add PREFIX prov: <http://www.w3.org/ns/prov#>)") in " ".join(output.split()), output
    asked = tmp_path / "ask.rq"
    asked.write_text("ASK { ?s ?p ?o }")
    code, output = _run(["query", str(asked), "--model", "ventilation_case_study", *store])
    assert code == 2 and "not a SELECT query" in output
    code, output = _run(["query", str(tmp_path / "missing.rq"), *store])
    assert code == 2 and "missing.rq: no such file" in output
    broken.write_text("SELECT ?x WHERE { ?x ?p }")  # without --model: the syntax error first, not "give --model"
    code, output = _run(["query", str(broken), *store])
    assert code == 2 and "SPARQL syntax error at line 1" in output and "give --model" not in output, output
    pumps = tmp_path / "pumps.rq"  # no row: the header still says what the columns are
    pumps.write_text("PREFIX s4bldg: <https://saref.etsi.org/saref4bldg/>\n"
                     "SELECT ?pump (STR(?pump) AS ?name) WHERE { ?pump a s4bldg:Chiller }\n")
    code, output = _run(["query", str(pumps), "--model", "ventilation_case_study", *store])
    assert code == 0 and output == "pump,name\n", output


def test_calibrate_prints_estimates_metrics_and_the_error_per_operating_regime(tmp_path):
    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "2", "--seed", "3",
                               "-o", str(data)]).exit_code == 0
    stamps = [line.split(",")[0] for line in data.read_text().splitlines()[1:]]
    result = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--memory",
                                 "--train", f"{stamps[0]}/{stamps[143]}", "--test", f"{stamps[144]}/"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "Estimates (point" in result.output and "Metrics, test window" in result.output
    counted = re.search(r"(\d+) of (\d+) estimated parameters identified by these data", result.output)
    assert counted and 0 < int(counted[1]) <= int(counted[2])  # the verdicts counted under the table
    # fewer than half identified is said in a sentence, as it is on the school AHU (0 of 19)
    assert ("Only " in result.output) == (2 * int(counted[1]) < int(counted[2]))
    # an unidentified parameter's first reason in the table, the count of the others (all in --json)
    as_json = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--memory", "--json",
                                  "--train", f"{stamps[0]}/{stamps[143]}", "--test", f"{stamps[144]}/"])
    estimates = json.loads(as_json.output)["parameters"].values()
    several = [e for e in estimates if not e["identified"] and len(e["reasons"]) > 1]
    assert several and len(re.findall(r"\(\+\d+ more in\s+--json\)", result.output)) == len(several)
    regimes = result.output[result.output.index("Test RMSE per operating regime"):]
    assert "supply air flow meter" in regimes and " %" in regimes and "°C" in regimes  # rules, shares, units
    refused = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--memory", "--gp-input", "supply_air_flow"])
    assert refused.exit_code == 2 and "a point calibration has no discrepancy" in refused.output
    no_start = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--memory", "--start-from", "v0"])
    assert no_start.exit_code == 2 and "--memory starts an empty one: drop --memory" in no_start.output
    no_start = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--store", str(tmp_path / "store"),
                                   "--start-from", "v0"])
    assert no_start.exit_code == 2 and "start from 'v0': no such model in the store" in no_start.output


def test_a_regime_the_test_window_never_enters_is_left_out_and_said_so():
    from types import SimpleNamespace

    from service.cli import printing

    sensor = EX + "coil_outlet_air_temperature_sensor"
    record = SimpleNamespace(regime_rule_accuracy=1.0, metrics={"test": {sensor: SimpleNamespace(unit="degC")}}, regimes=[
        {"rule": "setpoint > 18.5 °C", "share": 1.0, "rmse": {sensor: 0.31}},
        {"rule": "setpoint ≤ 14 °C", "share": 0.0, "rmse": {sensor: float("nan")}}])
    with printing.console.capture() as captured:
        printing.print_regimes(record)
    rows = {line.split("│")[1].strip(): line for line in captured.get().splitlines() if line.count("│") > 2}
    assert "0.31 K" in rows["setpoint > 18.5 °C"]
    assert "setpoint ≤ 14 °C" not in rows and "nan" not in captured.get()
    assert "1 regime(s) the test window never enters left out" in captured.get()


def test_the_command_line_starts_without_the_calibration_libraries():
    """`graphtwin --help`, `assemble` and `query` do not import SciPy's optimisers or scikit-learn (a
    second of start-up); the commands that calibrate import them when they run."""
    probe = ("import sys, service.cli; print(sorted(m for m in ('scipy.optimize', 'sklearn', 'numba', "
             "'service.diagnosis.loop', 'service.calibration.run') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.strip()
    assert loaded == "[]"


def test_a_mistyped_store_and_a_file_name_that_is_no_model_name_are_said_as_such(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for command in (["history", "model"], ["query", "calibrated-parameters"], ["report", "run-1", "-o", "r.html"]):
        result = runner.invoke(app, [*command, "--store", "nowhere"])
        assert result.exit_code == 2 and "no store at nowhere" in result.output, (command, result.output)
    assert not (tmp_path / "nowhere").exists()  # not created empty
    spaced = tmp_path / "my flexlab (v2).ttl"
    spaced.write_bytes(CASE_STUDY.read_bytes())
    result = runner.invoke(app, ["assemble", str(spaced), "--memory"])
    assert result.exit_code == 2 and "model name 'my flexlab (v2)'" in result.output and "--name" in result.output
    assert runner.invoke(app, ["assemble", str(spaced), "--memory", "--name", "flexlab"]).exit_code == 0


def test_example_generate_refuses_data_of_fewer_than_two_steps(tmp_path):
    for days in ("0.01", "-1"):
        result = runner.invoke(app, ["example", "generate", "ventilation_case_study", f"--days={days}", "-o", str(tmp_path / "x.csv")])
        assert result.exit_code == 2 and f"{float(days):g} days of data: give at least two steps of 10 min" in result.output
        assert not (tmp_path / "x.csv").exists()


def test_a_bayesian_runs_metrics_show_the_90_percent_intervals_ace_and_width(monkeypatch):
    from types import SimpleNamespace

    from rich.console import Console

    from service.calibration.metrics import IntervalCoverage
    from service.cli import printing

    printed = Console(record=True, width=200)
    monkeypatch.setattr(printing, "console", printed)
    common = dict(rmse=0.1, mae=0.08, r2=0.9, cv_rmse_percent=1.0, nmbe_percent=0.2, unit="degC", noise=0.05)
    printing.print_metrics("Metrics, test window", {
        EX + "a_sensor": SimpleNamespace(**common, coverage=(IntervalCoverage(0.5, 0.52, 0.02, 0.1),
                                                             IntervalCoverage(0.9, 0.87, -0.03, 0.33))),
        EX + "b_sensor": SimpleNamespace(**common, coverage=())})
    text = printed.export_text()
    assert "ACE 90 %" in text and "90 % width" in text
    assert any("a_sensor" in line and "-3.0" in line and "0.33" in line for line in text.splitlines())
    assert "RMSE / σ" in text and any("a_sensor" in line and " 0.05 " in line and " 2.0 " in line
                                       for line in text.splitlines())
    printing.print_metrics("Metrics, train window", {EX + "a_sensor": SimpleNamespace(**common, coverage=())})
    assert "ACE" not in printed.export_text()  # a point fit has no intervals


def test_a_calibration_written_to_a_file_says_how_far_sampling_is(tmp_path, monkeypatch):
    """No terminal, no progress bar: each convergence check the sampler reports is a line."""
    import service.workflows.runs as runs
    from service.errors import CalibrationError

    def sampling(store, request, data, *, progress=False, on_progress=None):
        on_progress("sampling: step 100 of 2000 expected (at most 4000), IAT 12")
        raise CalibrationError("stopped here")

    monkeypatch.setattr(runs, "calibrate_model", sampling)
    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "1", "-o", str(data)]).exit_code == 0
    result = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--memory", "--method", "bayes"])
    assert result.exit_code == 2 and "sampling: step 100 of 2000 expected (at most 4000), IAT 12…" in result.output


def test_output_to_a_file_or_pipe_is_as_wide_as_a_log_is_read_and_columns_still_decides():
    """No terminal to measure: tables are laid out 160 columns wide (rich would fold them at 80); a
    COLUMNS the user sets still decides."""
    from service.cli.common import PIPED_WIDTH

    wide = runner.invoke(app, ["example", "list"], env={"COLUMNS": None})
    row = next(line for line in wide.output.splitlines() if line.startswith("ventilation_case_study"))
    assert row.rstrip().endswith("ventilation_case_study/model.ttl") and 80 < len(row) <= PIPED_WIDTH, row
    narrow = runner.invoke(app, ["example", "list"], env={"COLUMNS": "60"})
    row = next(line for line in narrow.output.splitlines() if line.startswith("ventilation_case_study"))
    assert not row.rstrip().endswith("model.ttl")  # folded at 60


def test_metrics_of_data_logged_in_fahrenheit_say_what_a_kelvin_of_error_is_in_the_datas_degrees():
    """The errors are in K, the model's unit; a user whose columns are in °F reads the caption."""
    import numpy as np

    from service.calibration.metrics import target_metrics
    from service.cli.common import console
    from service.cli.printing import print_metrics

    observed = np.linspace(10.0, 20.0, 50) + np.random.default_rng(0).normal(0.0, 0.1, 50)
    metrics = {EX + "sat": target_metrics(observed, np.linspace(10.0, 20.0, 50), n_parameters=1, unit="degC",
                                          target=EX + "sat")}
    with console.capture() as captured:
        print_metrics("Metrics", metrics, {EX + "sat": "http://qudt.org/vocab/unit/DEG_F"})
    assert "as logged: 1 K = 1.8 °F" in captured.get()
    with console.capture() as captured:
        print_metrics("Metrics", metrics)
    assert "as logged" not in captured.get()


def test_the_samplers_step_limit_is_an_option_of_a_bayesian_calibration_only(tmp_path):
    """A run that did not converge by the fixed 4,000 steps could not be run longer: ``--max-steps``
    (and ``max_steps`` over HTTP) sets the limit; a point fit has no sampler and refuses it."""
    from service.workflows.requests import CalibrateRequest

    data = tmp_path / "data.csv"
    assert runner.invoke(app, ["example", "generate", "ventilation_case_study", "--days", "1", "-o", str(data)]).exit_code == 0
    refused = runner.invoke(app, ["calibrate", str(CASE_STUDY), str(data), "--memory", "--max-steps", "300"])
    assert refused.exit_code == 2 and "max_steps limits the sampler of a Bayesian calibration" in refused.output
    assert CalibrateRequest(model="m", measurements="0123456789abcdef", method="bayes", max_steps=8000).max_steps == 8000
    with pytest.raises(ValueError, match="greater than or equal to 200"):
        CalibrateRequest(model="m", measurements="0123456789abcdef", method="bayes", max_steps=10)


def test_ctrl_c_inside_compiled_sampling_code_ends_the_command_with_one_line_and_exit_code_130():
    """Ctrl-C while sampling printed a 279-line traceback ending in numba's "SystemError: …
    returned a result with an exception set"; any other SystemError is still a defect shown whole."""
    import typer

    from service.cli.common import reports_errors

    def sampling():
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("CPUDispatcher(<function _loop_step>) returned a result with an exception set")

    with pytest.raises(typer.Exit) as stopped:
        reports_errors(sampling)()
    assert stopped.value.exit_code == 130

    def broken():
        raise SystemError("a defect")

    with pytest.raises(SystemError, match="a defect"):
        reports_errors(broken)()


def test_the_discrepancy_gp_of_a_bayesian_run_is_a_table_in_physical_units():
    """The KOH discrepancy's amplitude, noise and length scales were in no output: how much misfit the
    GP absorbed could not be seen. Each is its posterior median with the 16–84 % interval."""
    from types import SimpleNamespace

    from service.cli.common import console
    from service.cli.printing import print_discrepancy

    record = SimpleNamespace(discrepancy={EX + "sat": {"amplitude": (0.05, 0.03, 0.08, "K"),
                                                       "length_scale:time": (3.2, 2.0, 6.5, "h")},
                                          EX + "fan_power_meter": {"amplitude": (12.0, 8.0, 20.0, "W")}})
    with console.capture() as captured:
        print_discrepancy(record)
    text = captured.get()
    assert "0.05 K (0.03–0.08)" in text and "3.2 h (2–6.5)" in text and "12 W (8–20)" in text
    assert "length scale, time" in text and "–" in text  # the meter has no length scale row entry
