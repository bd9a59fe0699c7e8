"""Drift candidates: a parameter that changes over time, for what the effect catalog lacks.

The simulator's parameter schedule against runs at constant values; on data from graphtwin's own
case-study generator with a parameter made to change by a schedule written here (runs at different
values spliced, not the drift code), the drift at the right parameter ranks first with its size near
the truth; on fault-free data no drift is significant.
"""

from pathlib import Path

import numpy as np
import pytest
from case_study import CASE_STUDY, EX

from service.calibration.metrics import noise_level
from service.calibration.model_data import ModelData
from service.calibration.run import calibrate
from service.components.library import SignatureLibrary
from service.data.model_series import read_model_data
from service.data.synthetic import generate_synthetic_data
from service.diagnosis.candidates import rank_catalog
from service.diagnosis.drift import (
    MAX_PARAMETERS_PER_COMPONENT,
    MIN_SENSITIVITY,
    DriftEvidence,
    drift_beyond_range,
    drift_candidates,
    drift_sentence,
)
from service.diagnosis.loop import diagnose
from service.graph.store import GraphStore
from service.graph.units import quantity_text
from service.model.assembled_model import ParameterDrift
from service.model.assembly import assemble
from service.model.simulator import loop_substeps
from service.report.stored_run import read_diagnosis

LIBRARY = SignatureLibrary.load()
TRAIN, TEST = ("2026-01-12", "2026-01-13T23:59"), ("2026-01-14", None)
COIL = EX + "heating_coil_air_side"
AIR_SIDE = "#air_side_conductance"
#: The catalog effects a change of the coil's conductance could be mistaken for: heat at the coil, a
#: leaking valve, an offset coil sensor (the whole catalog against each hidden catalog effect, with
#: the drifts competing, is test_diagnosis_loop's; this keeps each test under a minute).
LOOKALIKES = {name: s for name, s in LIBRARY.items()
              if s.kind != "effect" or name in ("ConstantHeatGain", "ValveLeakage", "SensorOffset")}


def _store() -> GraphStore:
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    return store


def _rows(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _drifting_data(tmp_path: Path, store: GraphStore, value_from, seed: int = 2) -> tuple[Path, float]:
    """Four days of case-study data whose ``air_side_conductance`` is ``value_from(p₀)`` →
    [(start time, value)]: from each start on, the rows of a run of the generator with that value
    (same seed: the same operation, the other parameters and the noise draws alike). Returns the
    file and p₀."""
    first = generate_synthetic_data(store, "case", tmp_path / "base.csv", library=LIBRARY, seed=seed, n_days=4.0)
    key = next(k for k in first.theta if k.endswith(AIR_SIDE))
    rows = _rows(tmp_path / "base.csv")
    for start, value in value_from(first.theta[key]):
        generate_synthetic_data(store, "case", tmp_path / "piece.csv", library=LIBRARY, seed=seed, n_days=4.0,
                                truth={key: value})
        piece = _rows(tmp_path / "piece.csv")
        rows = [rows[0]] + [new if np.datetime64(old.split(",")[0][:19]) >= np.datetime64(start) else old
                            for old, new in zip(rows[1:], piece[1:])]
    path = tmp_path / "data.csv"
    path.write_text("\n".join(rows) + "\n")
    return path, first.theta[key]


# --- the simulator's parameter schedule -----------------------------------------------------------


@pytest.fixture(scope="module")
def case_data(tmp_path_factory):
    store = _store()
    path = tmp_path_factory.mktemp("schedule") / "data.csv"
    generate_synthetic_data(store, "case", path, library=LIBRARY, seed=1, n_days=2.0)
    model = assemble(store, "case", library=LIBRARY)
    data = read_model_data(model, path)
    return ModelData(model, data, loop_substeps(model, data.step_s))


def _key(md: ModelData, suffix: str) -> tuple[str, int]:
    column = next(j for j, ref in enumerate(md.model.estimated_parameters) if ref.key.endswith(suffix))
    return md.model.estimated_parameters[column].key, column


@pytest.mark.parametrize("suffix", ["#c1", AIR_SIDE])  # the fan, evaluated over all steps at once; the coil, stepped
def test_a_constant_factor_is_the_parameter_scaled(case_data, suffix):
    md = case_data
    key, column = _key(md, suffix)
    window = slice(36, 200)
    theta = md.default_theta()
    scaled = theta.copy()
    scaled[column] *= 1.2
    factor = np.full((1, md.time_s(window).size), 1.2)
    with_factor = md.simulate_targets(window, theta, factors={key: factor})
    for node, values in md.simulate_targets(window, scaled).items():
        np.testing.assert_allclose(with_factor[node], values, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("suffix", ["#c1", AIR_SIDE])
def test_a_step_schedule_equals_two_runs_spliced(case_data, suffix):
    """Before the step every target is the run at the old value; after it a memoryless component's
    output (the fan's power) is the run at the new value at once, what passes through states (the
    fan's impeller heat through the coil, a stepped component's outputs) once they and the control
    loop have followed (within 1 % of the change's effect after 12 h: near shut-off an
    equal-percentage valve passes a trickle, and the water in the pipes takes hours to be replaced)."""
    md = case_data
    key, column = _key(md, suffix)
    window, step = slice(36, 250), 100  # the step at the window's 100th step
    theta = md.default_theta()
    old, new = theta.copy(), theta.copy()
    new[column] *= 0.7
    factor = np.where(md.time_s(window) >= (window.start + step) * md.data.step_s, 0.7, 1.0)[None, :]
    scheduled = md.simulate_targets(window, old, factors={key: factor})
    before, after = md.simulate_targets(window, old), md.simulate_targets(window, new)
    settled = step + int(12 * 3600 / md.data.step_s)
    moved = False
    for node in scheduled:
        np.testing.assert_array_equal(scheduled[node][0, :step], before[node][0, :step])
        change = np.max(np.abs(after[node][0] - before[node][0]))
        moved |= change > 1e-6
        if suffix == "#c1" and node == EX + "fan_power_meter":
            np.testing.assert_allclose(scheduled[node][0, step:], after[node][0, step:], rtol=1e-12, atol=1e-12)
        else:
            assert np.max(np.abs(scheduled[node][0, settled:] - after[node][0, settled:])) <= 0.01 * change + 1e-9, node
    assert moved


def test_a_drift_s_factor_is_linear_from_its_onset_or_a_step():
    times = np.array([-3600.0, 0.0, 43200.0, 86400.0])
    linear = ParameterDrift("urn:c#p", "linear", 0.0, "urn:c#p_drift_per_day").factor(np.array([-0.1, 0.2]), times)
    np.testing.assert_allclose(linear, [[1.0, 1.0, 0.95, 0.9], [1.0, 1.0, 1.1, 1.2]])
    step = ParameterDrift("urn:c#p", "step", 43200.0, "urn:c#p_step").factor(np.array([-0.3]), times)
    np.testing.assert_allclose(step, [[1.0, 1.0, 0.7, 0.7]])


def test_a_factor_of_the_wrong_shape_or_for_no_parameter_is_refused(case_data):
    md = case_data
    key, _ = _key(md, AIR_SIDE)
    window = slice(36, 60)
    with pytest.raises(ValueError, match="shape"):
        md.simulate_targets(window, md.default_theta(), factors={key: np.ones((1, 3))})
    with pytest.raises(ValueError, match="no parameter"):
        md.simulate_targets(window, md.default_theta(), factors={"urn:nothing#p": np.ones((1, md.time_s(window).size))})


def test_each_failing_sensor_gets_the_drifts_that_would_show_at_it(case_data):
    """The coil's parameters screened against two failing sensors, the coil's inlet and outlet water:
    each sensor's own most telling parameters (each parameter changed by 10 % from the test start in
    a run of its own here) get candidates, so a parameter that moves only the less-failing sensor is
    tried too (the coil's conductance, where the pipe's parameters move the inlet water most); the
    time constants of stored water and heat, fixed by construction, never."""
    md = case_data
    test, fit = slice(150, 288), slice(36, 150)
    theta = md.default_theta()
    coil = md.model.component_for_node(COIL).iri
    keys = [ref.key for ref in md.model.estimated_parameters if ref.component == coil and ref.spec.drifts]
    fixed = {ref.key for ref in md.model.estimated_parameters if ref.component == coil and not ref.spec.drifts}
    noise = {EX + "coil_inlet_water_temperature_sensor": 0.1, EX + "coil_outlet_water_temperature_sensor": 0.1}
    base = md.simulate_targets(test, theta)
    after = (md.time_s(test) >= test.start * md.data.step_s).astype(float)[None, :]
    moved = {node: {} for node in noise}
    for key in keys:
        changed = md.simulate_targets(test, theta, factors={key: 1.0 + 0.1 * after})
        for node, sigma in noise.items():
            moved[node][key] = float(np.sqrt(np.nanmean((changed[node] - base[node]) ** 2))) / sigma
    most = {node: sorted(keys, key=lambda k: -moved[node][k])[:MAX_PARAMETERS_PER_COMPONENT] for node in noise}
    expected = {key for node in noise for key in most[node] if moved[node][key] >= MIN_SENSITIVITY}
    tried = {c.model.drifts[0].parameter_key for c in drift_candidates(md, theta, [coil], test=test, fit_windows=[fit],
                                                                        noise=noise)}
    assert tried == expected and len(expected) > MAX_PARAMETERS_PER_COMPONENT, (sorted(tried), moved)
    assert len(fixed) == 4 and not tried & fixed  # a pipe's water content, a coil's heat capacity: never tried


def test_a_drift_that_takes_its_parameter_out_of_its_range_is_implausible_and_ends_in_its_unit(case_data):
    """A drift fitted past what the component can be (a school AHU's outdoor-air fraction drifted to
    1.19, its range 0.5–1) is demoted with the value it reaches; inside the range nothing is said."""
    md = case_data
    test, fit = slice(150, 288), slice(36, 150)
    coil = md.model.component_for_node(COIL).iri
    noise = {EX + "coil_inlet_water_temperature_sensor": 0.1, EX + "coil_outlet_water_temperature_sensor": 0.1}
    candidates = drift_candidates(md, md.default_theta(), [coil], test=test, fit_windows=[fit], noise=noise)
    for candidate in candidates:
        model = candidate.model
        refs = model.estimated_parameters
        drift = model.drifts[0]
        column = next(j for j, r in enumerate(refs) if r.key == drift.parameter_key)
        spec = refs[column].spec
        theta = np.append(md.default_theta(), 0.0)
        theta[column] = 0.9 * spec.upper
        days = (test.stop - 1 - drift.onset_s / md.data.step_s) * md.data.step_s / 86400.0
        size = 0.5 if drift.shape == "step" else 0.5 / days  # 1.35 × the upper bound by the end
        theta[-1] = size
        reason = drift_beyond_range(model, theta, md.data.step_s, test.stop - 1)
        assert f"the {spec.name} it drifts to, " in reason and "lies outside its range" in reason, reason
        assert f"{1.35 * spec.upper:.4g}" in reason
        theta[-1] = size / 10  # 0.945 × the upper bound: inside
        assert drift_beyond_range(model, theta, md.data.step_s, test.stop - 1) == ""
        sentence = drift_sentence(model, theta, np.full(theta.size, 0.01), md.data.timestamps, md.data.step_s,
                                  test.stop - 1)
        reached = theta[column] * (1.0 + theta[-1] * (days if drift.shape == "linear" else 1.0))  # 0.945 × upper
        assert quantity_text(reached, spec.unit, ".4g") in sentence, sentence  # a plain number ("1") shows no unit
    assert {c.model.drifts[0].shape for c in candidates} == {"linear", "step"}


# --- drift found where it is, and not where it is not ----------------------------------------------


@pytest.mark.slow
def test_a_step_in_the_coil_s_air_side_conductance_is_named_first_with_its_size(tmp_path):
    """The air-side hA falls by 30 % at 08:00 on the test window's first day (off the 6-hour grid):
    the step drift of air_side_conductance at the coil ranks first, significant, ahead of its
    look-alikes in the catalog, its jump within ±0.05 of −0.30 and its onset within an hour of 08:00."""
    store = _store()
    path, _ = _drifting_data(tmp_path, store, lambda p0: [("2026-01-14T08:00", 0.7 * p0)])
    report = diagnose(store, "case", path, train=TRAIN, test=TEST, seed=0, refit_max_nfev=20, library=LOOKALIKES)
    best = report.effects[0]
    assert isinstance(best, DriftEvidence) and best.significant, [(e.effect, e.test_improvement) for e in report.effects[:4]]
    assert (best.effect, best.node) == ("StepDrift/air_side_conductance", COIL), best.explanation
    assert abs(best.estimates["air_side_conductance_step"] + 0.30) <= 0.05, best.estimates
    assert abs(np.datetime64(best.onset) - np.datetime64("2026-01-14T08:00")) <= np.timedelta64(1, "h"), best.onset
    # the model kept with the evidence (for the look-alike checks) steps where the fit put the onset
    assert np.datetime64("2026-01-12T00:00") + np.timedelta64(int(best.model.drifts[0].onset_s), "s") == np.datetime64(best.onset)
    assert "air_side_conductance of heating_coil_air_side" in report.summary and " drops " in report.summary
    assert report.to_dict()["answer"]["drift"] == {"parameter": "air_side_conductance", "shape": "step",
                                                   "onset": best.onset}
    stored = read_diagnosis(store, report.run_id).effects[0]  # written as triples, read back as the report page does
    assert (stored.effect, stored.label, stored.node) == ("StepDrift/air_side_conductance",
                                                          "Step change of air_side_conductance", COIL)


@pytest.mark.slow
def test_a_linear_fall_of_the_coil_s_air_side_conductance_is_named_first_with_its_rate(tmp_path):
    """The air-side hA falls 12 % a day from the test window's start (a staircase of 2-hour runs):
    the linear drift of air_side_conductance at the coil ranks first, significant, its rate within
    ±0.03 a day of −0.12."""
    start = np.datetime64("2026-01-14T00:00")
    store = _store()
    path, _ = _drifting_data(tmp_path, store, lambda p0: [
        (start + np.timedelta64(hours, "h"), p0 * (1.0 - 0.12 * (hours + 1) / 24.0)) for hours in range(0, 48, 2)])
    report = diagnose(store, "case", path, train=TRAIN, test=TEST, seed=0, refit_max_nfev=20, library=LOOKALIKES)
    best = report.effects[0]
    assert best.significant and (best.effect, best.node) == ("LinearDrift/air_side_conductance", COIL), (
        [(e.effect, e.test_improvement, e.delta_bic) for e in report.effects[:4]])
    assert abs(best.estimates["air_side_conductance_drift_per_day"] + 0.12) <= 0.03, best.estimates
    assert " falls " in best.explanation and " a day from 2026-01-14 00:00" in best.explanation


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3])
def test_on_fault_free_data_no_drift_is_significant(tmp_path, seed):
    """Every parameter the screen picks at the coil, both shapes, refitted on fault-free data as if
    its sensors failed: none is significant (the false alarms the drift candidates add)."""
    store = _store()
    path = tmp_path / "data.csv"
    generate_synthetic_data(store, "case", path, library=LIBRARY, seed=seed, n_days=4.0)
    base = calibrate(store, "case", path, train=TRAIN, test=TEST, seed=0, min_test_steps=12)
    md = base.model_data
    predicted = base.predictions["test"]
    observed = md.observed(base.test)
    noise = {node: noise_level(observed[node] - predicted[node], md.units[node], observed[node]) for node in observed}
    no_catalog = {name: s for name, s in LIBRARY.items() if s.kind != "effect"}
    ranked, _ = rank_catalog(store, "case", no_catalog, base, seed=0, refit_max_nfev=20, workers=None,
                             say=lambda message: None, drifting=[md.model.component_for_node(COIL).iri],
                             failing_noise=noise)
    assert len(ranked) >= 2 and all(isinstance(e, DriftEvidence) for e in ranked)
    assert not any(e.significant for e in ranked), [(e.effect, e.delta_bic, e.test_improvement) for e in ranked]
