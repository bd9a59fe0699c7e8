"""The open-fdd school AHU 7 (../shared/realdata/openfdd_ahu7_school): a real Brick model of a real
unit, written by its points only. What holds whatever the data: what assembles from the file as it
is, what the Brick report says is missing, and that stating what it names completes the model."""

import csv
import re

import pyoxigraph as ox
import pytest
from shared_data import SCHOOL

from service.calibration.run import calibrate
from service.components.library import SignatureLibrary
from service.data.synthetic import generate_synthetic_data
from service.diagnosis.loop import diagnose
from service.errors import IncompleteModelError
from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.model.effect_recording import applied_effect_triples
from service.report.brick import brick_report

AHU7 = "http://openfdd.local/ahu7#"
#: What the report asks for: an official class for the fan speed command, units for the commands.
FIXES = """
@prefix brick: <https://brickschema.org/schema/Brick#> .
@prefix unit:  <http://qudt.org/vocab/unit/> .
@prefix : <http://openfdd.local/ahu7#> .
:sf_spd_cmd a brick:Fan_Speed_Command ; brick:hasUnit unit:PERCENT .
:oa_damper_cmd brick:hasUnit unit:PERCENT .
:clg_valve_cmd brick:hasUnit unit:PERCENT .
:prht_valve_cmd brick:hasUnit unit:PERCENT .
"""

pytestmark = pytest.mark.skipif(not (SCHOOL / "ahu7_brick_model.ttl").is_file(),
                                reason=f"{SCHOOL} is absent (../shared/realdata)")


@pytest.fixture(scope="module")
def store():
    store = GraphStore.embedded(None)
    ttl = (SCHOOL / "ahu7_brick_model.ttl").read_bytes()
    store.load_model("school", ttl)
    store.load_model("school-fixed", ttl + FIXES.encode())
    return store


#: The winter week's days of the comparisons below; the condition that leaves the fan-off steps out.
WINTER_DAYS = dict(train=("2025-01-02", "2025-01-03 23:59"), test=("2025-01-06", "2025-01-06 23:59"))
FAN_ON = ["SF Spd Cmd (%) > 5"]
FAN_ON_WINDOW = dict(**WINTER_DAYS, only_when=FAN_ON)


@pytest.fixture(scope="module")
def winter_comparison(store):
    """``graphtwin compare`` of the base model on the winter days, every step compared."""
    return diagnose(store, "school-fixed", SCHOOL / "AHU7.csv", seed=0, rank_effects=False, **WINTER_DAYS)


@pytest.fixture(scope="module")
def fan_on_comparison(store):
    """``graphtwin compare`` of the base model on the winter days, fan-off steps left out."""
    return diagnose(store, "school-fixed", SCHOOL / "AHU7.csv", seed=0, rank_effects=False, **FAN_ON_WINDOW)


def test_the_file_as_it_is_lacks_a_fan_and_the_report_says_why(store):
    with pytest.raises(IncompleteModelError, match="ahu_7_supply_fan"):
        assemble(store, "school")
    report = brick_report(store, "school")
    unaligned = {c.class_iri.removeprefix("https://brickschema.org/schema/Brick#"): c for c in report.unaligned_classes}
    assert set(unaligned) == {"Supply_Fan_Speed_Command", "Supply_Air_Static_Pressure_Sensor",
                              "Supply_Air_Temperature_Setpoint", "Site"}
    assert "brick:Fan_Speed_Command" in unaligned["Supply_Fan_Speed_Command"].needed
    assert report.points_without_unit == tuple(AHU7 + p for p in ("clg_valve_cmd", "oa_damper_cmd", "prht_valve_cmd"))
    # units from the non-QUDT namespace the file uses, columns from the labels: assumed, and said so
    rules = {}
    for a in report.assumptions:
        rules.setdefault(a.rule, set()).add(a.about.removeprefix(AHU7))
    assert rules["04-brick-point-links.rq"] == {"oat_sensor", "rat_sensor", "mat_sensor", "sat_sensor",
                                                "oa_damper_cmd", "clg_valve_cmd", "prht_valve_cmd"}
    assert rules["56-brick-sensor-placement.rq"] == {"oat_sensor", "rat_sensor", "mat_sensor", "sat_sensor"}
    assert rules["00-brick-ahu-equipment.rq"] == {"ahu_7"}


def test_the_assumptions_read_whole_at_80_columns_nodes_by_their_local_names(store):
    """The table a user reads to remove an assumption: IRIs had been cut to "http://openfdd.l…"."""
    from rich.console import Console

    from service.report.brick import brick_report, print_brick_report

    console = Console(width=80, record=True)
    print_brick_report(brick_report(store, "school-fixed"), console)
    text = console.export_text()
    assert "Assumptions made where the model is ambiguous" in text and "http://openfdd.l…" not in text
    caption = " ".join(text[text.index("nodes by their local names, in"):].split())
    assert AHU7 in caption  # the namespace said once
    assert "http://openfdd.local/ahu7#ahu" not in "".join(text.split())
    assert "<ahu_7>" in text
    # its units are Brick 1.x's, taken for QUDT's: the two told apart, not both read <DEG_F>
    assert "<bu:DEG_F>" in text and "<unit:DEG_F>" in text and "<DEG_F>" not in text
    assert "bu: http://brickschema.org/schema/Brick/units#" in caption
    # what to state is Turtle to paste (it read "<mat_sensor> brick:hasUnit <unit:DEG_F> ."): the model's
    # nodes under the empty prefix and QUDT's units under unit:, both declared in the caption
    import pyoxigraph as ox

    wide = Console(width=250, record=True)
    print_brick_report(brick_report(store, "school-fixed"), wide)
    flat = " ".join(wide.export_text().split())
    declarations = " ".join(re.findall(r"@prefix [\w]*: <[^>]+> \.", caption))
    assert "@prefix : <http://openfdd.local/ahu7#> ." in declarations and "@prefix unit: <http://qudt.org/vocab/unit/> ." in declarations
    assert ":mat_sensor brick:hasUnit unit:DEG_F ." in flat
    triples = list(ox.parse(f"{declarations} :mat_sensor brick:hasUnit unit:DEG_F .".encode(), ox.RdfFormat.TURTLE))
    assert [(t.subject.value, t.object.value) for t in triples] == [(AHU7 + "mat_sensor", "http://qudt.org/vocab/unit/DEG_F")]


def test_with_what_the_report_names_the_unit_assembles_and_links_to_the_csv(store):
    model = assemble(store, "school-fixed")
    chosen = {c.node.removeprefix(AHU7): c.signature.id for c in model.components.values()}
    assert {n: s for n, s in chosen.items() if s not in ("CommandSignal", "TemperatureSensor")} == {
        "ahu_7_mixing_section": "MixingBox", "prht_valve_cmd_coil": "HeatingCoil",
        "clg_valve_cmd_coil": "CoolingCoil", "ahu_7_supply_fan": "SpeedControlledFan"}
    assert sorted(model.components[t].node.removeprefix(AHU7) for t in model.targets) == ["mat_sensor", "sat_sensor"]
    with (SCHOOL / "AHU7.csv").open(newline="", encoding="utf-8") as handle:
        headers = set(next(csv.reader(handle)))
    links = [c.measurement for c in model.components.values() if c.measurement]
    assert len(links) == 8 and sorted(link.series_id for link in links if link.series_id not in headers) == []
    assert brick_report(store, "school-fixed").points_without_unit == ()


def test_a_winter_week_compared_fails_at_the_mixed_air_with_the_fan_off(winter_comparison):
    """Calibrated on 2–3 January 2025 and compared on Monday 6 January: the model fails at the mixed
    and the supply air, the failure sits in the mixing section (the outdoor and return air sensors
    are boundary inputs the model matches by construction), and the worst regime is the fan off in
    the cold. With the fan off the preheat valve stands at 100 % and the mixed air sensor reads up
    to 94 °F: it sees still air warmed by the coil, not an air stream, which the mixing model cannot
    reproduce (docs/brick.md records the full diagnosis)."""
    report = winter_comparison
    assert not report.effects_tested and report.effects == []
    assert {n.removeprefix(AHU7) for n, s in report.sensors.items() if s.fails} == {"mat_sensor", "sat_sensor"}
    assert report.sensors[AHU7 + "mat_sensor"].rmse > 5.0
    located = {(loc.matching_sensor.removeprefix(AHU7), loc.failing_sensor.removeprefix(AHU7)): loc.components
               for loc in report.localization if not loc.upstream_fails}
    assert set(located) == {("oat_sensor", "mat_sensor"), ("rat_sensor", "mat_sensor")}
    assert all(AHU7 + "ahu_7_mixing_section" in components for components in located.values())
    # the supply air's error is not the mixed air's carried down (with the fan off they read still air
    # differently): it grows between them, where the preheat coil is
    [grown] = [loc for loc in report.localization if loc.upstream_fails]
    assert [grown.matching_sensor, grown.failing_sensor] == [AHU7 + "mat_sensor", AHU7 + "sat_sensor"]
    assert any("prht" in c for c in grown.components), grown
    worst = next(r for r in report.regimes if r["worst"])
    assert "sf spd cmd ≤" in worst["rule"] and worst["share"] > 0.2, worst
    mat_episodes = report.episodes[AHU7 + "mat_sensor"]
    assert str(mat_episodes[0].start).startswith("2025-01-06T00:00"), mat_episodes[0]
    # the data file's outdoor air temperature freezes at 70 °F from 9 January: said, for the sensor only
    frozen = [w for w in report.data_warnings if "frozen point" in w]
    assert len(frozen) == 1 and frozen[0].startswith("column 'OAT (°F)': holds 70 °F exactly from 2025-01-09"), frozen


def test_the_cli_points_an_incomplete_brick_model_to_its_report(tmp_path):
    import json

    from typer.testing import CliRunner

    from service.cli import app

    runner = CliRunner()
    model = SCHOOL / "ahu7_brick_model.ttl"
    failed = runner.invoke(app, ["assemble", str(model), "--memory"])
    assert failed.exit_code == 2 and "ahu_7_supply_fan" in failed.output and "brick-report" in failed.output
    result = runner.invoke(app, ["brick-report", str(model), "--memory", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert {c["class_iri"].rsplit("#", 1)[1] for c in report["unaligned_classes"]} >= {"Supply_Fan_Speed_Command"}
    assert len(report["points_without_unit"]) == 3
    fixed = tmp_path / "school.ttl"
    fixed.write_bytes(model.read_bytes() + FIXES.encode())
    assert runner.invoke(app, ["assemble", str(fixed), "--memory"]).exit_code == 0


def test_with_the_fan_off_left_out_the_supply_air_matches_and_the_mixed_air_error_falls(store, winter_comparison,
                                                                                    fan_on_comparison):
    """--only-when 'SF Spd Cmd (%) > 5': the nights with the fan off (still air by the preheat coil)
    are simulated but not compared. The supply air then matches within its noise and the mixed air
    error falls to a quarter (what is left: the mixing section in operation); the filter is recorded
    with the run, and a condition on a column the file does not have is refused by name."""
    everything, running = winter_comparison, fan_on_comparison
    assert not running.sensors[AHU7 + "sat_sensor"].fails
    assert running.sensors[AHU7 + "mat_sensor"].rmse < 0.4 * everything.sensors[AHU7 + "mat_sensor"].rmse
    settings = store.query("SELECT ?s WHERE { GRAPH ?g { ?run <https://w3id.org/graphtwin/ontology#settings> ?s } }",
                           substitutions={"run": ox.NamedNode(f"https://w3id.org/graphtwin/resource/run/{running.run_id}")})
    assert '"only_when": ["SF Spd Cmd (%) > 5"]' in settings[0]["s"].value
    # the file's other numeric columns may filter too (the fan status the model does not read): a name
    # the file lacks is refused, naming what it has
    with pytest.raises(ValueError, match=r"operating condition on 'Occupied'.*known: .*SF Spd Cmd.*SF Sts"):
        diagnose(store, "school-fixed", SCHOOL / "AHU7.csv", only_when=["Occupied > 0"], **WINTER_DAYS)


@pytest.fixture(scope="module")
def recirculation(store):
    """The model with ReturnFlowOffFanSpeed at the mixing section, calibrated on the fan-on steps."""
    signature = SignatureLibrary.load()["ReturnFlowOffFanSpeed"]
    effect = ox.serialize(applied_effect_triples(signature, AHU7 + "ahu_7_mixing_section"), format=ox.RdfFormat.TURTLE)
    store.load_model("school-recirculation", (SCHOOL / "ahu7_brick_model.ttl").read_bytes() + FIXES.encode() + b"\n" + effect)
    return calibrate(store, "school-recirculation", SCHOOL / "AHU7.csv", **FAN_ON_WINDOW).record


def test_recirculated_air_not_following_the_supply_fan_cuts_the_mixed_air_error(fan_on_comparison, recirculation):
    """What the fan-on residual follows (the supply fan speed) is an effect of the catalog: this unit's
    return fan runs at a fixed 20 % while the supply fan varies, so the recirculated flow does not
    scale with the supply flow (ReturnFlowOffFanSpeed). Added to the model, calibrated on the same
    days, it cuts the mixed air test error by a fifth (3.1 → 2.5 K; asserted: 15 %), the supply
    air's unchanged, with an exponent well off its null."""
    base = fan_on_comparison.sensors
    mixed, supply = AHU7 + "mat_sensor", AHU7 + "sat_sensor"
    assert recirculation.metrics["test"][mixed].rmse < 0.85 * base[mixed].rmse
    assert recirculation.metrics["test"][supply].rmse < 1.1 * base[supply].rmse
    exponent = next(e for e in recirculation.estimates if e.name == "recirculation_speed_exponent")
    assert 0.2 < exponent.median < 1.5, exponent


def test_recalibrated_from_the_base_fit_the_version_ends_no_worse_than_fitted_afresh(store, fan_on_comparison,
                                                                                     recirculation):
    """``--start-from``, the loop's recalibration after add-effect: the stored start is run besides the
    starts a fresh fit screens, so it ends no worse than that fit (it took one of the two starts'
    places before: 2.88 K mixed air, β 0.17 and cost 160.1, against 2.46 K, 0.38 and 157.9 fresh)."""
    warm = calibrate(store, "school-recirculation", SCHOOL / "AHU7.csv", start_from="school-fixed",
                     **FAN_ON_WINDOW).record
    assert warm.settings["start_from"]["model"] == "school-fixed"
    assert warm.diagnostics.cost <= recirculation.diagnostics.cost * (1 + 1e-9), (
        warm.diagnostics.cost, recirculation.diagnostics.cost)


@pytest.mark.slow
def test_on_the_units_own_operation_a_hidden_recirculation_effect_is_found(store, recirculation, tmp_path):
    """Semi-synthetic: the school's measured boundary inputs drive a known truth, the unit as the model
    with the effect calibrated it (β ≈ 0.38), with sensor noise; the base model is diagnosed on it.
    The mixed air fails and the effect ranks first, significant, at the mixing section: on real
    operation the loop finds this effect when it is there (on the real data it is not significant:
    docs/brick.md)."""
    given = {e.key: e.median for e in recirculation.estimates}  # keys match without their model name
    data = tmp_path / "semi-synthetic.csv"
    generate_synthetic_data(store, "school-fixed", data, library=SignatureLibrary.load(),
                            hidden_effect="ReturnFlowOffFanSpeed", seed=1, operation=SCHOOL / "AHU7.csv", truth=given)
    report = diagnose(store, "school-fixed", data, seed=0, refit_max_nfev=20, **FAN_ON_WINDOW)
    assert report.sensors[AHU7 + "mat_sensor"].fails
    best = report.effects[0]
    assert (best.effect, best.node, best.significant) == ("ReturnFlowOffFanSpeed", AHU7 + "ahu_7_mixing_section", True), \
        [(e.effect, e.test_improvement) for e in report.effects[:3]]


def test_regime_rules_read_in_the_columns_units(winter_comparison):
    """The fan speed command is logged in %, the temperatures in °F: the rules say "≤ 11%" and °F,
    as --only-when takes a condition (not the simulator's fraction 0.11 and °C)."""
    worst = next(r for r in winter_comparison.regimes if r["worst"])
    assert "sf spd cmd ≤ 11%" in worst["rule"] and "°F" in worst["rule"] and "°C" not in worst["rule"], worst
