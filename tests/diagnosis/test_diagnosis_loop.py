"""The diagnosis loop on synthetic data with a hidden effect, for every effect the case study admits,
and the control without one (the method must not invent effects)."""

from pathlib import Path

import numpy as np
import pytest
from case_study import CASE_STUDY, EX, case_study_data, case_study_with_effect

from service.calibration.metrics import noise_level
from service.components.library import SignatureLibrary
from service.data.model_series import read_model_data
from service.data.synthetic import NOISE_STD, generate_synthetic_data
from service.diagnosis.loop import diagnose
from service.graph.store import GraphStore
from service.model.assembly import assemble

LIBRARY = SignatureLibrary.load()
TRAIN = ("2026-01-12", "2026-01-13T23:59")
TEST = ("2026-01-14", None)
#: Where each effect is hidden: where the case study's sensors can see it.
HIDDEN = {
    "FanMotorHeat": EX + "supply_fan",
    "ValveLeakage": EX + "heating_valve",
    "ValveStuck": EX + "heating_valve",
    "SensorOffset": EX + "coil_outlet_water_temperature_sensor",
    "SensorLag": EX + "coil_outlet_air_temperature_sensor",
    "WaterSensorLag": EX + "coil_outlet_water_temperature_sensor",
    "DuctHeatExchange": EX + "heating_coil_air_side",
    "DuctHeatExchangeUnmeasured": EX + "heating_coil_air_side",
    "ConstantHeatGain": EX + "heating_coil_air_side",
}


#: The case study in a plant room with a measured temperature (DuctHeatExchange needs surroundings).
PLANT_ROOM = Path(__file__).parent.parent / "fixtures" / "plant_room.ttl"


def _diagnose(tmp_path, effect, node, *, disturbance: bool = False):
    """The diagnosis of four generated days with ``effect`` hidden at ``node``; with ``disturbance``,
    also each sensor's RMS difference on the evaluation half between those data and the same days
    generated without the effect (the same seed: the same operation, parameters and noise draws, so
    the difference is what the effect alone does to each reading)."""
    store = GraphStore.embedded(None)
    extra = PLANT_ROOM.read_bytes() if effect == "DuctHeatExchange" else b""
    store.load_model("case", CASE_STUDY.read_bytes() + b"\n" + extra)
    data = tmp_path / "data.csv"
    generate_synthetic_data(store, "case", data, library=LIBRARY, hidden_effect=effect, node=node, seed=2, n_days=4.0)
    report = diagnose(store, "case", data, train=TRAIN, test=TEST, seed=0)  # the refits' default budget
    if not disturbance:
        return report
    without = tmp_path / "without.csv"
    generate_synthetic_data(store, "case", without, library=LIBRARY, seed=2, n_days=4.0)
    model = assemble(store, "case")
    hidden, base = read_model_data(model, data), read_model_data(model, without)
    evaluation = hidden.window(TEST[0], TEST[1])
    return report, {n: float(np.sqrt(np.nanmean((hidden.series[n][evaluation] - base.series[n][evaluation]) ** 2)))
                    for n in hidden.series}


def test_every_catalog_effect_the_case_study_admits_is_tested_here():
    # CoilThermalMass extends static coils only (the FLEXLAB model's), not the hot-water loop;
    # ReturnFlowOffFanSpeed needs a mixing box (tested on the school AHU's data, tests/model/test_brick_school.py)
    applicable = {s.id for s in LIBRARY.values() if s.kind == "effect"} - {"CoilThermalMass", "ReturnFlowOffFanSpeed"}
    assert applicable == set(HIDDEN)


@pytest.mark.slow
@pytest.mark.parametrize("effect", sorted(HIDDEN))
def test_the_hidden_effect_ranks_first_and_adding_it_halves_the_error(tmp_path, effect):
    report, disturbance = _diagnose(tmp_path, effect, HIDDEN[effect], disturbance=True)
    best = report.effects[0]
    assert best.significant, report.summary
    assert (best.effect, best.node) == (effect, HIDDEN[effect]), [(e.effect, e.node, e.test_improvement) for e in report.effects[:3]]
    # the sensors the hidden effect moves beyond the truth's measurement noise on the evaluation half
    # (the data against the same days generated without it); with the effect added and fitted on
    # other data, their RMSE there halves, or is within the noise floor (an RMSE cannot fall below the
    # noise; a base refit that absorbed part of the effect leaves less than the disturbance to halve)
    noise = {n: NOISE_STD.get(report.sensors[n].unit, report.sensors[n].noise) for n in best.rmse_before}
    affected = [n for n in best.rmse_before if disturbance[n] > 1.5 * noise[n]]
    assert affected, (disturbance, noise)
    for node in affected:
        assert best.rmse_after[node] <= max(0.5 * best.rmse_before[node], 1.1 * noise[node]), (
            node, best.rmse_before, best.rmse_after)
    assert best.explanation and effect in report.summary
    assert ("that sensor's test error (the refit's other parameters kept); against the base model it removes "
            f"{100 * best.test_improvement:.0f} % of the test error over all sensors") in best.explanation
    # one story: the answer is located on the flow path, at the sensors where it removes error
    shown = [n for n, verdict in report.sensors.items() if verdict.located]
    assert shown and all(best.error_removed_at(n) >= 0.2 or report.sensors[n].fails for n in shown)
    assert any(best.node in loc.components or best.node == loc.failing_sensor for loc in report.localization), (
        best.node, [loc.to_dict() for loc in report.localization])


def test_nothing_is_invented_when_nothing_is_missing(tmp_path):
    report = _diagnose(tmp_path, None, None)
    assert not report.significant, [(e.effect, e.delta_bic, e.test_improvement) for e in report.effects[:3]]
    assert "nothing significant is missing" in report.to_dict()["summary"] or not any(
        s.fails for s in report.sensors.values())
    assert report.to_dict()["nothing_significant_missing"] is True


@pytest.mark.slow
def test_the_report_follows_the_cli_contract_and_is_stored(tmp_path):
    data = tmp_path / "data.csv"
    store, _ = case_study_data(data, library=LIBRARY, hidden_effect="ValveLeakage", seed=2, n_days=4.0)
    report = diagnose(store, "case", data, train=TRAIN, test=TEST, seed=0, refit_max_nfev=20)
    out = report.to_dict()
    for node, metrics in out["sensors"].items():
        assert set(metrics) >= {"rmse", "mae", "cv_rmse", "nmbe", "unit"}
    assert all(set(loc) >= {"between", "components"} for loc in out["localization"])
    assert out["localization"], "a leaking valve must be located"
    assert any(EX + "heating_valve" in loc["components"] or EX + "heating_coil_air_side" in loc["components"]
               for loc in out["localization"])
    assert all({"rule", "share", "rmse"} <= set(r) for r in out["regimes"])
    first = out["effects"][0]
    assert set(first) >= {"effect", "target", "score", "p_value", "delta_bic", "explanation", "rmse_after"}
    rows = store.query(
        "PREFIX gt: <https://w3id.org/graphtwin/ontology#> SELECT ?effect ?rank WHERE { GRAPH ?g { "
        "?c a gt:EffectCandidate ; gt:candidateEffect ?effect ; gt:rank ?rank } } ORDER BY ?rank")
    assert rows[0]["effect"].value == first["effect"]


def test_an_operating_filter_holds_for_the_base_fit_and_every_candidate_refit(tmp_path):
    """Compared only where the fan runs above its median flow: the base and every candidate are
    fitted on the same steps, so an effect (which nests the base at its null) never fits worse,
    ΔBIC ≤ k·ln n, and the hidden fan motor heat fits best, its true size within 3 standard errors
    (0.850 ± 0.035 against 0.8 since the targets are weighted by their robust range).
    On this one filtered day its out-of-sample gain is lost to the fan curve, which its refit moves
    on half the flow range (fan power test RMSE 10.6 → 12.0 W against 5 W of noise): the ranking,
    which puts the out-of-sample gain first, does not list it first here, and calls nothing
    significant."""
    import numpy as np

    from service.data.measurements import SeriesSpec, read_measurements

    data = tmp_path / "data.csv"
    store, _ = case_study_data(data, library=LIBRARY, hidden_effect="FanMotorHeat", seed=2, n_days=2.0)
    flow = read_measurements(data, {"f": SeriesSpec("f", "supply_air_flow", "http://qudt.org/vocab/unit/M3-PER-SEC",
                                                    "m3/s")}).series["f"]
    condition = f"supply_air_flow > {np.nanmedian(flow):.4f}"
    catalog = {k: s for k, s in LIBRARY.items() if s.kind != "effect" or k in ("FanMotorHeat", "SensorOffset")}
    report = diagnose(store, "case", data, train=("2026-01-12", "2026-01-12T23:59"), test=("2026-01-13", None),
                      seed=0, library=catalog, refit_max_nfev=10, workers=1, only_when=[condition])
    n = 2 * 144 * len(report.sensors)
    assert all(e.delta_bic <= len(e.parameter_names) * np.log(n) for e in report.effects), [
        (e.effect, e.node, e.delta_bic) for e in report.effects]
    best = min(report.effects, key=lambda e: e.delta_bic)
    assert best.effect == "FanMotorHeat" and best.delta_bic < -10
    estimate, standard_error = best.estimates["motor_heat_fraction"], best.standard_errors["motor_heat_fraction"]
    truth = LIBRARY["FanMotorHeat"].extra["synthetic_truth"]["motor_heat_fraction"]
    assert abs(estimate - truth) <= 3.0 * standard_error < 0.15, (estimate, truth, standard_error)
    # the output says what the filter kept of each window
    kept = [w for w in report.data_warnings if w.startswith(f"compared only where {condition}: ")]
    assert [w.split(": ")[1].split(" of the ")[1] for w in kept] == ["training window's 144 steps",
                                                                     "test window's 144 steps"], kept


def test_an_operating_filter_that_keeps_no_step_of_a_window_is_named():
    from types import SimpleNamespace

    import numpy as np
    import pytest

    from service.calibration.run import _operating_filter_notes

    md = SimpleNamespace(compared=np.r_[np.zeros(10, bool), np.ones(10, bool)])
    assert _operating_filter_notes(md, ["valve > 0.9"], slice(10, 20), slice(12, 20)) == [
        "compared only where valve > 0.9: 10 of the training window's 10 steps",
        "compared only where valve > 0.9: 8 of the test window's 8 steps"]
    with pytest.raises(ValueError, match=r"--only-when valve > 0.9 holds at none of the 10 steps of the training window"):
        _operating_filter_notes(md, ["valve > 0.9"], slice(0, 10), slice(10, 20))


def test_the_worst_regime_spans_enough_steps_to_be_a_regime_not_a_spike():
    """A fan start-up regime of one step with an 11 K spike was named the school AHU's worst over the
    half day with a steady 2.5 K misfit; a regime needs MIN_TEST_STEPS steps to be named worst."""
    from service.diagnosis.loop import MIN_TEST_STEPS, _regimes_with_worst
    from service.diagnosis.report import SensorVerdict

    node = "urn:x#mat"
    verdict = SensorVerdict(rmse=3.0, mae=2.0, cv_rmse_percent=1.0, nmbe_percent=0.0, r2=0.5, unit="degC",
                            noise=0.1, fails=True)
    rows = [{"regime": 0, "rule": "start-up", "share": 1 / 96, "rmse": {node: 11.4}},
            {"regime": 1, "rule": "fan on", "share": 0.5, "rmse": {node: 2.5}},
            {"regime": 2, "rule": "fan off", "share": 95 / 192, "rmse": {node: 0.3}}]
    assert [r["worst"] for r in _regimes_with_worst([dict(r) for r in rows], {node: verdict}, 96)] == [
        False, True, False]
    assert rows[0]["share"] * 96 < MIN_TEST_STEPS <= rows[1]["share"] * 96  # one step against 48
    short = [dict(r, share=r["share"] / 10) for r in rows]  # no regime spans enough: the largest RMSE
    assert [r["worst"] for r in _regimes_with_worst(short, {node: verdict}, 96)] == [True, False, False]
    # the summary's sentence on the worst sensor names the same regime (it had named the one-step spike)
    from service.diagnosis.report import DiagnosisReport

    report = DiagnosisReport(model_name="m", run_id="r", sensors={node: verdict}, localization=[],
                             regimes=_regimes_with_worst([dict(r) for r in rows], {node: verdict}, 96),
                             regime_rule_accuracy=1.0, episodes={}, effects=[], not_applicable=[],
                             test_timestamps=np.arange(96))
    assert "its error is largest where fan on (RMSE 2.5 K over 50 %" in report.residual_structure()


def test_the_noise_floor_of_a_power_meter_is_its_accuracy_of_reading():
    """A 500 W meter read 4 W (0.8 %) low with 0.3 W of noise: within its ±1 % accuracy, so its noise
    level is 5 W (1 % of the reading), not 1 % of the small residual — it does not "fail"."""
    rng = np.random.default_rng(0)
    observed = 500.0 + 50.0 * np.sin(np.arange(288) / 20.0) + rng.normal(0.0, 0.3, 288)
    residual = np.full(288, 4.0) + rng.normal(0.0, 0.3, 288)
    assert noise_level(residual, "W", observed) == pytest.approx(0.01 * np.mean(np.abs(observed)))
    # a temperature keeps its absolute floor of 0.1 K, whatever the reading
    assert noise_level(rng.normal(0.0, 0.01, 288), "degC", observed) == pytest.approx(0.1)



@pytest.mark.parametrize("seed", range(5))
def test_a_meter_whose_noise_is_proportional_to_its_reading_gets_its_rms_noise(seed):
    """2 % of a fan power that is 300 W at night and 3 kW by day: the RMS noise (~ 2 % of the RMS
    reading) within 15 %, where one quartile over all steps gives the night's; a temperature's
    additive noise is still its σ."""
    rng = np.random.default_rng(seed)
    hours = np.arange(1008) / 6.0
    observed = np.where((hours % 24 > 6) & (hours % 24 < 20), 3000.0, 300.0) + 50.0 * np.sin(hours)
    noise = 0.02 * observed * rng.standard_normal(observed.size)
    truth = float(np.sqrt(np.mean(noise**2)))
    assert noise_level(noise, "W", observed + noise) == pytest.approx(truth, rel=0.15)
    assert noise_level(rng.normal(0.0, 0.3, 1008), "degC", observed) == pytest.approx(0.3, rel=0.15)


def test_an_effect_the_model_records_is_not_offered_again():
    from service.diagnosis.candidates import effect_candidates

    store = GraphStore.embedded(None)
    store.load_model("case", case_study_with_effect(LIBRARY["FanMotorHeat"], EX + "supply_fan"))
    candidates, skipped = effect_candidates(store, "case", LIBRARY)
    offered = {(signature.id, node) for signature, node, _model in candidates}
    assert ("FanMotorHeat", EX + "supply_fan") not in offered and ("ValveLeakage", EX + "heating_valve") in offered
    assert "FanMotorHeat at supply_fan: already in the model (gt:hasEffect)" in skipped


@pytest.mark.parametrize("extra, general, specific, node", [
    (b"", "SensorLag", "WaterSensorLag", "coil_outlet_water_temperature_sensor"),
    (PLANT_ROOM.read_bytes(), "DuctHeatExchangeUnmeasured", "DuctHeatExchange", "heating_coil_air_side"),
])
def test_an_effect_is_not_offered_where_one_it_yields_to_applies(extra, general, specific, node):
    """A water sensor's lag is the water lag alone (the air lag's 30 minutes are its special case); in
    a plant room with a measured temperature the duct exchanges heat with that room, not with
    surroundings of unknown temperature. Elsewhere the general effect is still offered."""
    from service.diagnosis.candidates import effect_candidates

    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY.read_bytes() + b"\n" + extra)
    candidates, skipped = effect_candidates(store, "case", LIBRARY)
    offered = {(signature.id, node) for signature, node, _model in candidates}
    assert (specific, EX + node) in offered and (general, EX + node) not in offered
    assert (f"{general} at {node}: {specific} applies there, which it yields to "
            f"(yields_to in {LIBRARY[general].source_file.name})") in skipped
    if extra:  # without the room the duct's surroundings are unmeasured
        store.load_model("bare", CASE_STUDY)
        assert (general, EX + node) in {(s.id, n) for s, n, _ in effect_candidates(store, "bare", LIBRARY)[0]}
    else:  # an air sensor is on no water path
        assert ("SensorLag", EX + "coil_outlet_air_temperature_sensor") in offered


@pytest.mark.slow
def test_an_effect_is_not_credited_with_what_the_refit_base_parameters_gain(tmp_path):
    """Fan motor heat hidden (3 days, seed 1): a valve stuck with a weight of ~0.0002 improves the
    evaluation half mostly through the base parameters its refit moves (set the weight back to 0 and
    most of the gain stays). Judged against the better of the base refit and its own base parameters
    with the effect nulled, it is not significant (nor is leakage); the hidden effect is, and ranks
    first. The other significant candidates put heat into the supply air too, and rank far behind: an
    offset of the controlled sensor (+0.54 K), which in the closed loop mimics heat upstream of the
    coil (490 behind in ΔBIC), and a constant heat gain at the coil's air side (270 W where the fan's
    heat follows its power; 1,200 behind)."""
    data = tmp_path / "data.csv"
    store, _ = case_study_data(data, library=LIBRARY, hidden_effect="FanMotorHeat", seed=1, n_days=3.0)
    report = diagnose(store, "case", data, train=("2026-01-12", "2026-01-13T23:50"), test=TEST, seed=0)
    summary = [(e.effect, e.node, e.estimates, e.delta_bic, e.test_improvement) for e in report.effects[:3]]
    significant = [e for e in report.effects if e.significant]
    assert significant, summary
    first, *others = significant
    assert (first.effect, first.node) == ("FanMotorHeat", EX + "supply_fan") and report.effects[0] is first, summary
    heat_into_the_air = {("SensorOffset", EX + "coil_outlet_air_temperature_sensor"),
                         ("ConstantHeatGain", EX + "heating_coil_air_side")}
    assert all((e.effect, e.node) in heat_into_the_air and e.delta_bic > first.delta_bic + 100 for e in others), summary


def test_a_refit_stopped_at_its_evaluation_limit_says_so_and_is_ranked_below_the_converged(tmp_path):
    """Issue 32 (5): a refit that stops on its iteration limit is continued, and one still short
    says so, in its demotion and its sentence, and is ranked below the converged candidates of its
    significance. Two evaluations cannot fit a hidden leak's refit; forty can."""
    data = tmp_path / "data.csv"
    store, _ = case_study_data(data, library=LIBRARY, hidden_effect="ValveLeakage", seed=2, n_days=2.0)
    catalog = {k: s for k, s in LIBRARY.items() if s.kind != "effect" or k in ("ValveLeakage", "SensorOffset")}

    def diagnosed(evaluations: int):
        return diagnose(store, "case", data, train=("2026-01-12", "2026-01-12T23:59"), test=("2026-01-13", None),
                        seed=0, library=catalog, refit_max_nfev=evaluations, workers=1).effects

    short = diagnosed(2)
    stopped = [e for e in short if "its refit did not converge in 4 runs of 2 evaluations" in e.demoted]
    assert stopped, [(e.effect, e.demoted) for e in short]
    assert all("did not converge" in e.explanation for e in stopped)
    for higher, lower in zip(short, short[1:]):
        assert (higher.significant, not higher.demoted) >= (lower.significant, not lower.demoted)
    leak = next(e for e in diagnosed(40) if e.effect == "ValveLeakage")
    assert "did not converge" not in leak.demoted, leak.demoted


def test_a_sensor_only_an_effect_reads_is_left_out_of_the_base_and_its_column_joins_the_data_for_that_effect(tmp_path):
    """The plant room's air temperature drives nothing in the base model, so the base leaves it out
    and needs no column for it; the duct's exchange with the room reads it, and its candidate gets the
    column from the file (as read for the model with the effect; ``rank_catalog``). A file without the
    column leaves that candidate untried, saying why."""
    from service.data.model_series import with_series_of
    from service.model.effect_splicing import EffectRequest

    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY.read_bytes() + b"\n" + PLANT_ROOM.read_bytes())
    data = tmp_path / "data.csv"
    generate_synthetic_data(store, "case", data, library=LIBRARY, hidden_effect="DuctHeatExchange",
                            node=EX + "heating_coil_air_side", seed=2, n_days=1.0)
    room = EX + "plant_room_air_temperature_sensor"
    base = assemble(store, "case")
    assert base.component_for_node(room) is None
    with_room = assemble(store, "case", extra_effects=[EffectRequest("DuctHeatExchange", EX + "heating_coil_air_side")])
    extended, lacking = with_series_of(read_model_data(base, data), with_room)
    assert lacking == [] and np.array_equal(extended.series[room], read_model_data(with_room, data).series[room],
                                            equal_nan=True)
    header = data.read_text().splitlines()[0].split(",")
    column = header.index("plant_room_air_temperature")
    lines = [",".join(c for i, c in enumerate(line.split(",")) if i != column) for line in data.read_text().splitlines()]
    without = tmp_path / "without_room.csv"
    without.write_text("\n".join(lines) + "\n")
    unchanged, lacking = with_series_of(read_model_data(base, without), with_room)
    assert lacking == ["plant_room_air_temperature"] and room not in unchanged.series
