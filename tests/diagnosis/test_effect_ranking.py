"""Score test, ΔBIC and ranking on analytic problems whose answer is known."""

import numpy as np
import pytest

from service.calibration.metrics import effective_sample_fraction
from service.calibration.problem import CalibrationProblem
from service.diagnosis.ranking import (
    EffectEvidence,
    ScoreTest,
    delta_bic,
    rank_evidence,
    score_test,
)

T = np.linspace(0.0, 10.0, 400)
X = np.sin(T)
Z = np.where(T > 5.0, 1.0, 0.0)  # the effect's signal: a step the base model cannot make


def _problem(true_b: float, lower_b: float = 0.0, seed: int = 0) -> CalibrationProblem:
    rng = np.random.default_rng(seed)
    observed = 2.0 * X + true_b * Z + rng.normal(0.0, 0.05, T.size)

    def simulate(theta):
        return {"y": theta[:, :1] * X + theta[:, 1:2] * Z}

    return CalibrationProblem(
        parameter_names=("a", "b"), lower=np.array([0.0, lower_b]), upper=np.array([5.0, 2.0]),
        simulate=simulate, observed={"y": observed}, target_scales={"y": 0.05},
    )


def _base_estimate(problem):
    y = problem.observed["y"]
    return float(np.dot(X, y) / np.dot(X, X))


def test_score_test_detects_a_present_effect_and_predicts_the_likelihood_gain():
    problem = _problem(true_b=0.3)
    theta_null = np.array([_base_estimate(problem), 0.0])
    result = score_test(problem, theta_null, [1], sample_fractions=[1.0])
    # the exact gain of adding b at the optimum: RSS0 − RSS1 of a linear least-squares problem
    y = problem.observed["y"] / 0.05
    design = np.column_stack([X, Z]) / 0.05
    rss0 = np.sum((y - X / 0.05 * theta_null[0]) ** 2)
    rss1 = np.sum((y - design @ np.linalg.lstsq(design, y, rcond=None)[0]) ** 2)
    sigma2 = rss0 / (T.size - 1)
    assert result.statistic == pytest.approx((rss0 - rss1) / sigma2, rel=1e-3)
    assert result.p_value < 1e-10
    assert result.active_parameters == ("b",)


def test_score_test_is_quiet_without_the_effect():
    p_values = []
    for seed in range(20):
        problem = _problem(true_b=0.0, lower_b=-2.0, seed=seed)
        result = score_test(problem, np.array([_base_estimate(problem), 0.0]), [1], sample_fractions=[1.0])
        p_values.append(result.p_value)
    # a null in the interior: P(χ²₁ > S), as often below 0.01 as chance has it
    assert np.mean(np.array(p_values) < 0.01) <= 0.1


def test_an_effect_whose_step_overshoots_its_far_bound_counts_at_the_bound():
    """The demo's fan motor heat: the Gauss–Newton step from f = 0 went to 1.10 of at most 1. Held at
    its null for leaving its bounds, it scored 0 (p = 1) beside a ΔBIC of −7,835; at the bound it
    explains what a step of 2 there explains."""
    problem = _problem(true_b=3.0)  # b at most 2
    theta_null = np.array([_base_estimate(problem), 0.0])
    result = score_test(problem, theta_null, [1], sample_fractions=[1.0])
    y = problem.observed["y"] / 0.05
    rss0 = np.sum((y - X / 0.05 * theta_null[0]) ** 2)
    a_at_b2 = np.dot(X, y - 2.0 * Z / 0.05) / np.dot(X, X) * 0.05  # the base refitted with b at its bound
    rss_bound = np.sum((y - (a_at_b2 * X + 2.0 * Z) / 0.05) ** 2)
    assert result.statistic == pytest.approx((rss0 - rss_bound) / (rss0 / (T.size - 1)), rel=1e-3)
    assert result.active_parameters == ("b",) and result.p_value < 1e-10


def test_an_effect_the_bounds_forbid_scores_zero():
    problem = _problem(true_b=-0.3, lower_b=0.0)
    result = score_test(problem, np.array([_base_estimate(problem), 0.0]), [1], sample_fractions=[1.0])
    assert result.statistic == 0.0 and result.p_value == 1.0 and result.active_parameters == ()


def test_effective_sample_fraction_of_white_and_autocorrelated_noise():
    rng = np.random.default_rng(1)
    white = rng.normal(size=20_000)
    assert effective_sample_fraction(white) == pytest.approx(1.0, abs=0.03)
    ar = np.zeros(20_000)
    for i in range(1, ar.size):
        ar[i] = 0.9 * ar[i - 1] + white[i]
    assert effective_sample_fraction(ar) == pytest.approx(0.1 / 1.9, rel=0.1)


def test_delta_bic_sign_and_penalty():
    assert delta_bic(100.0, 50.0, 1000, 1) < 0
    assert delta_bic(100.0, 100.0, 1000, 1) == pytest.approx(np.log(1000))


def _evidence(effect, improvement, bic, n_par):
    return EffectEvidence(
        effect=effect, effect_iri=effect, node="n", label=effect,
        parameter_names=tuple(f"p{i}" for i in range(n_par)), score=ScoreTest(1.0, 0.5, 0.1, ()),
        delta_bic=bic, test_improvement=improvement,
    )


def test_ranking_prefers_significant_then_larger_improvement_then_the_better_bic():
    # a stuck valve nests a leak (w = λ at s = 1): fitting no better, it pays ln Σn_eff for s in its ΔBIC
    stuck = _evidence("ValveStuck", 0.904, -508.0, 2)
    leak = _evidence("ValveLeakage", 0.901, -515.0, 1)
    offset = _evidence("SensorOffset", 0.95, -3.0, 1)  # not significant by BIC
    weak = _evidence("SensorLag", 0.4, -40.0, 1)
    ranked = rank_evidence([stuck, offset, weak, leak])
    assert [e.effect for e in ranked] == ["ValveLeakage", "ValveStuck", "SensorLag", "SensorOffset"]
    assert [e.significant for e in ranked] == [True, True, True, False]


def test_where_the_held_out_shares_tie_the_in_sample_evidence_decides_before_the_parameter_count():
    # the reference plant's duct, seed 3: both remove 87 % of the held-out error, and the exchange's
    # two parameters fit the training data far better than the offset's one (ΔBIC −4,299 against −3,150)
    offset = _evidence("SensorOffset", 0.871, -3150.0, 1)
    duct = _evidence("DuctHeatExchangeUnmeasured", 0.868, -4299.0, 2)
    assert [e.effect for e in rank_evidence([offset, duct])] == ["DuctHeatExchangeUnmeasured", "SensorOffset"]
    equal = [_evidence("SensorOffset", 0.87, -3150.0, 1), _evidence("ConstantHeatGain", 0.87, -3150.0, 1)]
    assert [e.effect for e in rank_evidence(equal)] == ["ConstantHeatGain", "SensorOffset"]  # then by name


def test_an_estimate_at_a_bound_of_its_prior_is_flagged_in_the_explanation():
    from service.components.component import Parameter
    from service.diagnosis.plausibility import bound_note as _bound_note

    offset = Parameter("offset", "K", 0.0, -5.0, 5.0, "sensor offset", null=0.0)
    assert _bound_note(4.99999999961, offset) == " (at its upper bound 5 K)"
    assert _bound_note(-5.0, offset) == " (at its lower bound -5 K)"
    assert _bound_note(4.9, offset) == ""
    # relative to the prior's range: a 5 kW heat gain fitted at 4,990 W sits at its bound
    gain = Parameter("heat_gain", "W", 0.0, -5000.0, 5000.0, "heat gain", null=0.0)
    assert _bound_note(4990.0, gain) == " (at its upper bound 5000 W)" and _bound_note(4900.0, gain) == ""


def test_a_stuck_valve_entirely_stuck_or_wide_open_or_a_fit_at_the_null_is_the_effect_not_a_prior_cut_short():
    """A stuck valve's weight at 1 (entirely stuck) and its position at 0 or 1 (stuck shut or wide open)
    are states the physics reaches, and an effect fitted at its null bound is absent: none is flagged;
    a leak at its 0.8 limit is."""
    import dataclasses

    from service.components.effects.valve_leakage import ValveLeakage
    from service.components.effects.valve_stuck import ValveStuck
    from service.diagnosis.plausibility import bound_note as _bound_note

    weight, position = ValveStuck.parameters
    assert [_bound_note(v, weight) for v in (0.99999, 0.0, 0.9)] == ["", "", ""]
    assert [_bound_note(v, position) for v in (1.0, 0.0)] == ["", ""]
    assert _bound_note(0.8, ValveLeakage.parameters[0]) == " (at its upper bound 0.8)"
    with pytest.raises(ValueError, match=r"attainable \(0\.99,\) are not its bounds \[0\.0, 1\.0\]"):
        dataclasses.replace(weight, attainable=(0.99,))


def test_an_effect_fitted_only_at_a_bound_other_than_its_null_or_without_a_heat_source_is_ranked_below():
    """On the FLEXLAB unit: a heat gain at the heating coil at its 5 kW limit, or any heat gain into
    the air at the chilled-water coil (no heat source there), is demoted with the reason; a gain at
    the heating coil inside its range, or a loss at the cooling coil, is not. The ranking puts a
    demoted effect that removes more held-out error below a plausible one."""
    from service.diagnosis.plausibility import demotion_reasons
    from service.graph.store import GraphStore
    from service.model.assembly import assemble
    from service.model.effect_splicing import EffectRequest
    from service.resources import examples_dir

    flexlab = "https://example.org/flexlab-x3a#"
    store = GraphStore.embedded(None)
    store.load_model("flexlab", examples_dir() / "flexlab_ahu" / "model.ttl")

    def reasons(node: str, heat_w: float) -> str:
        model = assemble(store, "flexlab", extra_effects=[EffectRequest("ConstantHeatGain", flexlab + node)])
        column = next(j for j, r in enumerate(model.estimated_parameters) if r.name == "heat_gain")
        theta = np.array([r.spec.default for r in model.estimated_parameters])
        theta[column] = heat_w
        return demotion_reasons(model, flexlab + node, theta, [column])

    assert reasons("heating_coil", 4999.0) == "heat_gain fits only at its upper bound 5000 W"
    assert reasons("heating_coil", 3450.0) == "" and reasons("cooling_coil", -2000.0) == ""
    assert reasons("cooling_coil", 3450.0) == ("heat_gain = 3450 W into the air at cooling_coil, which can only take "
                                               "heat from the air (Chilled-water cooling coil driven by a valve command): no heat source there")
    bounded = _evidence("ConstantHeatGain", 0.8, -900.0, 1)
    bounded.demoted = "heat_gain fits only at its upper bound 5000 W"
    offset = _evidence("SensorOffset", 0.6, -300.0, 1)
    ranked = rank_evidence([bounded, offset])
    assert [e.effect for e in ranked] == ["SensorOffset", "ConstantHeatGain"] and all(e.significant for e in ranked)
    assert ranked[1].to_dict()["demoted"].startswith("heat_gain fits only")


@pytest.mark.parametrize(("example", "power_known"), [("flexlab_ahu", False), ("ventilation_case_study", True)])
def test_a_motor_heat_at_its_upper_bound_is_demoted_only_where_the_fans_power_is_known(example, power_known):
    """The motor heat is a share of the fan's power: with a power meter (the case study) a share at 1
    is the physics' limit; with none and no nominal power stated (FLEXLAB), the power is an assumed
    default, and a share at 1 says only that the heat exceeds it (a walkthrough's fault-free unit had
    its motor heat demoted so and a sensor offset named instead)."""
    from service.diagnosis.plausibility import demotion_reasons
    from service.graph.store import GraphStore
    from service.model.assembly import assemble
    from service.model.effect_splicing import EffectRequest
    from service.resources import examples_dir

    store = GraphStore.embedded(None)
    store.load_model("m", examples_dir() / example / "model.ttl")
    fan = next(c.node for c in assemble(store, "m").components.values() if "Fan" in c.signature.id)
    model = assemble(store, "m", extra_effects=[EffectRequest("FanMotorHeat", fan)])
    column = next(j for j, r in enumerate(model.estimated_parameters) if r.name == "motor_heat_fraction")
    theta = np.array([r.spec.default for r in model.estimated_parameters])
    theta[column] = 1.0
    assert demotion_reasons(model, fan, theta, [column]) == (
        "motor_heat_fraction fits only at its upper bound 1" if power_known else "")


def test_an_estimate_the_data_leave_anywhere_in_its_prior_is_called_not_identified():
    from service.components.component import Parameter
    from service.diagnosis.candidates import _estimate_text

    leak = Parameter("leakage_fraction", "1", 0.0, 0.0, 0.3, "leakage", null=0.0)
    assert _estimate_text("leakage_fraction", 0.21, 1.3e8, leak) == \
        "leakage_fraction = 0.21, not identified (the data leave it anywhere in [0, 0.3])"
    assert _estimate_text("leakage_fraction", 0.21, float("inf"), leak).endswith("[0, 0.3])")
    assert _estimate_text("leakage_fraction", 0.21, 0.02, leak) == "leakage_fraction = 0.21 ± 0.02"
    assert _estimate_text("leakage_fraction", 0.3, 0.02, leak) == "leakage_fraction = 0.3 ± 0.02 (at its upper bound 0.3)"
    gain = Parameter("heat_gain", "W", 0.0, -5000.0, 5000.0, "heat", null=0.0)  # a quantity with a unit says it
    assert _estimate_text("heat_gain", 1150.0, 4.4, gain) == "heat_gain = 1.15e+03 ± 4.4 W"


def _two_targets(seed: int, b: float = 0.0, power_scale: float = 0.05) -> CalibrationProblem:
    """A temperature (white noise 0.05 K, weighted by it) and a power meter of the same signal ×50
    with AR(1) noise (ρ = 0.9, 1 W innovations) weighted as if it were a temperature: the diagnosis's
    case of a power meter among temperature targets."""
    rng = np.random.default_rng(seed)
    temperature = 2.0 * X + b * Z + rng.normal(0.0, 0.05, T.size)
    power_noise = np.zeros(T.size)
    innovations = rng.normal(0.0, 1.0, T.size)
    for i in range(1, T.size):
        power_noise[i] = 0.9 * power_noise[i - 1] + innovations[i]

    def simulate(theta):
        signal = theta[:, :1] * X + theta[:, 1:2] * Z
        return {"temperature": signal, "power": 50.0 * signal}

    return CalibrationProblem(
        parameter_names=("a", "b"), lower=np.array([0.0, -2.0]), upper=np.array([5.0, 2.0]), simulate=simulate,
        observed={"temperature": temperature, "power": 50.0 * (2.0 * X + b * Z) + power_noise},
        target_scales={"temperature": 0.05, "power": power_scale},
    )


def _null_estimate(problem: CalibrationProblem) -> np.ndarray:
    """The base fit: a by weighted least squares with b = 0 (the model is linear in a)."""
    design = np.concatenate([50.0 ** (key == "power") * X / problem.target_scales[key] for key in problem.observed])
    y = np.concatenate([problem.observed[key] / problem.target_scales[key] for key in problem.observed])
    return np.array([float(design @ y / (design @ design)), 0.0])


def test_the_score_test_holds_its_size_with_a_power_meter_among_the_targets():
    """Each target over its own noise variance and effective sample size: with one pooled variance
    and one n_eff from the concatenated residuals the rejection rate at α = 0.05 was 24 % here
    (300 draws). Band: the binomial 99.9 % upper limit of a 5 % rate over 200 draws."""
    p_values = np.array([score_test(problem, _null_estimate(problem), [1]).p_value
                         for problem in (_two_targets(seed) for seed in range(200))])
    assert np.mean(p_values < 0.05) <= 0.05 + 3.1 * np.sqrt(0.05 * 0.95 / 200)
    powered = np.array([score_test(problem, _null_estimate(problem), [1]).p_value
                        for problem in (_two_targets(seed, b=0.03) for seed in range(50))])
    assert np.mean(powered < 0.05) >= 0.8  # a 0.03 K step (0.6 σ) is found


def test_the_score_statistic_does_not_depend_on_the_weight_a_target_was_given():
    light, heavy = _two_targets(3, b=0.01), _two_targets(3, b=0.01, power_scale=5.0)
    assert score_test(light, _null_estimate(light), [1]).statistic == pytest.approx(
        score_test(heavy, _null_estimate(heavy), [1]).statistic, rel=0.02)


def test_a_null_on_its_bound_is_tested_against_the_mixture():
    """S ~ ½χ²₀ + ½χ²₁ for one parameter on its bound, ¼χ²₀ + ½χ²₁ + ¼χ²₂ for two."""
    from scipy.stats import chi2

    from service.diagnosis.ranking import bounded_null_p_value

    assert bounded_null_p_value(3.0, 0, 1) == pytest.approx(0.5 * chi2.sf(3.0, 1))
    assert bounded_null_p_value(3.0, 0, 2) == pytest.approx(0.5 * chi2.sf(3.0, 1) + 0.25 * chi2.sf(3.0, 2))
    assert bounded_null_p_value(3.0, 1, 0) == pytest.approx(chi2.sf(3.0, 1))
    assert bounded_null_p_value(0.0, 1, 1) == 1.0
    rng = np.random.default_rng(0)  # the mixture's size: simulated from its definition
    draws = np.maximum(rng.normal(size=(20_000, 2)), 0.0) ** 2
    assert np.mean([bounded_null_p_value(s, 0, 2) < 0.05 for s in draws.sum(axis=1)]) == pytest.approx(0.05, abs=0.006)


def test_delta_bic_sums_each_targets_likelihood_and_counts_every_freed_parameter():
    # a target whose error halves and one unchanged: only the first speaks; two freed parameters pay twice
    assert delta_bic([100.0, 10.0], [50.0, 10.0], [30.0, 5.0], 1) == pytest.approx(30 * np.log(0.5) + np.log(35))
    assert delta_bic([100.0, 10.0], [50.0, 10.0], [30.0, 5.0], 3) - delta_bic(
        [100.0, 10.0], [50.0, 10.0], [30.0, 5.0], 1) == pytest.approx(2 * np.log(35))


def test_the_evidence_sentence_says_how_the_residual_follows_the_effect_or_that_it_adds_nothing():
    """A fitted effect that moves a sensor as its residual does is described by the cosine and the
    share it removes; one fitted at its null adds nothing, and says so (it had read "follows what …
    adds (cosine 0.00)")."""
    from service.diagnosis.candidates import _explain

    t = np.arange(48.0)
    observed = {"a": 1.0 + 0.5 * np.sin(t / 5), "b": 2.0 + 0.0 * t}
    null = {"a": np.ones_like(t), "b": 2.0 + 0.0 * t}
    evidence = EffectEvidence("E", "urn:E", "urn:n", "E", ("k",), ScoreTest(0.0, 0.0, 1.0, ("k",)), test_improvement=0.4)
    _explain(evidence, observed, null, {"a": observed["a"], "b": null["b"]}, "E at n", "fit", "", {"a": 1.0, "b": 1.0})
    assert evidence.explanation.startswith("residual on a follows what E at n adds (cosine 1.00); it removes 100 % of "
                                           "that sensor's test error")
    assert evidence.explanation.endswith("against the base model it removes 40 % of the test error over all sensors; fit")
    _explain(evidence, observed, null, null, "E at n", "fit", "", {"a": 1.0, "b": 1.0})
    assert evidence.explanation.startswith("E at n, as fitted, adds nothing at any sensor (it sits at its null); ")
    evidence.test_improvement = -0.99  # a walkthrough's refit landed elsewhere: not the effect's doing
    _explain(evidence, observed, null, null, "E at n", "fit", "", {"a": 1.0, "b": 1.0})
    assert "grows 99 % (the refit's other parameters moved it, not the effect); fit" in evidence.explanation


def test_a_leaks_stem_position_is_also_said_as_the_share_of_the_open_flow_its_valve_passes():
    """A user read "leakage_fraction = 0.287 ± 0.023" as a 29 % leak; through the fitted equal-percentage
    characteristic (R = 7.7) it passes 14 % of the open flow, at R = 99 under 3 %, and the data did not
    pin R. The sentence says the share at the fitted characteristic, and its range over R's prior where
    R is not identified (over ±2 standard errors where it is). On a FLEXLAB coil's linear valve λ is
    the share already: nothing more is said."""
    from case_study import EX

    from service.diagnosis.plausibility import flow_share_text
    from service.graph.store import GraphStore
    from service.model.assembly import assemble
    from service.model.effect_splicing import EffectRequest
    from service.resources import examples_dir

    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    model = assemble(store, "case", extra_effects=[EffectRequest("ValveLeakage", EX + "heating_valve")])
    refs = model.estimated_parameters
    leak = next(j for j, r in enumerate(refs) if r.name == "leakage_fraction")
    rangeability = next(j for j, r in enumerate(refs) if r.name == "valve_rangeability")
    theta = np.array([r.spec.default for r in refs])
    theta[leak], theta[rangeability] = 0.287, 7.7
    unidentified = np.full(len(refs), np.inf)
    share = 7.7 ** (0.287 - 1) - (1 - 0.287) / 7.7
    at_99 = 99 ** (0.287 - 1) - (1 - 0.287) / 99
    text = flow_share_text(model, EX + "heating_valve", theta, unidentified, [leak])
    assert text.startswith(f"at leakage_fraction 0.287 the valve passes {100 * share:.2g} % of its fully open flow "
                           "coefficient (valve_rangeability = 7.7; ")
    low, high = (float(v) for v in text.split("; ")[1].split(" %")[0].split("–"))
    assert low == pytest.approx(100 * at_99, abs=0.5) and high == pytest.approx(28.7, abs=0.5)  # R = 100 … R = 1
    assert text.endswith("over the whole range of valve_rangeability, which these data do not identify)")
    identified = unidentified.copy()
    identified[rangeability] = 0.5
    assert "±2 standard errors of it" in flow_share_text(model, EX + "heating_valve", theta, identified, [leak])
    offset = assemble(store, "case", extra_effects=[EffectRequest("SensorOffset", EX + "coil_outlet_air_temperature_sensor")])
    assert flow_share_text(offset, EX + "coil_outlet_air_temperature_sensor",
                           np.array([r.spec.default for r in offset.estimated_parameters]), unidentified, [0]) == ""

    flexlab = "https://example.org/flexlab-x3a#"
    store.load_model("flexlab", examples_dir() / "flexlab_ahu" / "model.ttl")
    model = assemble(store, "flexlab", extra_effects=[EffectRequest("ValveLeakage", flexlab + "heating_coil_valve")])
    theta = np.array([r.spec.default for r in model.estimated_parameters])
    leak = next(j for j, r in enumerate(model.estimated_parameters) if r.name == "leakage_fraction")
    # a linear valve: the leak, acting on the stem past the actuator's dead band, is the open-flow share itself
    assert flow_share_text(model, flexlab + "heating_coil_valve", theta, np.full(theta.size, np.inf), [leak]) == ""


def test_unmeasured_surroundings_colder_than_every_reading_in_the_unit_are_stated_so():
    """A casing's exchange with surroundings at 5.6 ± 0.6 °C where the coldest temperature measured
    anywhere in the unit is 12.1 °C (a walkthrough's chilled-water valve leak was so named): the
    diagnosis says so, with the sensor that reads it. Within two standard errors of that reading,
    above it, or not identified, it says nothing."""
    from service.data.measurements import MeasuredData
    from service.diagnosis.plausibility import surroundings_caution
    from service.graph.store import GraphStore
    from service.model.assembly import assemble
    from service.model.effect_splicing import EffectRequest
    from service.resources import examples_dir

    flexlab = "https://example.org/flexlab-x3a#"
    store = GraphStore.embedded(None)
    store.load_model("flexlab", examples_dir() / "flexlab_ahu" / "model.ttl")
    model = assemble(store, "flexlab", extra_effects=[EffectRequest("DuctHeatExchangeUnmeasured", flexlab + "cooling_coil")])
    columns = [j for j, r in enumerate(model.estimated_parameters) if r.component == flexlab + "cooling_coil"
               or "DuctHeatExchangeUnmeasured" in r.component]
    column = next(j for j, r in enumerate(model.estimated_parameters) if r.name == "surroundings_temperature")
    theta = np.array([r.spec.default for r in model.estimated_parameters])
    errors = np.full(theta.size, 0.01)
    stamps = np.arange("2026-07-14T00:00", "2026-07-14T00:03", dtype="datetime64[m]").astype("datetime64[s]")
    data = MeasuredData(timestamps=stamps, step_s=60.0, units={"sat": "degC", "oat": "degC", "fan": "W"},
                        series={"sat": np.array([12.1, np.nan, 19.0]), "oat": np.array([19.7, 25.0, 30.0]),
                                "fan": np.array([-300.0, 0.0, 900.0])})

    def caution(surroundings_c: float, error_c: float) -> str:
        theta[column], errors[column] = surroundings_c, error_c
        return surroundings_caution(model, theta, errors, columns, data)

    assert caution(5.64, 0.63) == ("surroundings at 5.64 °C are colder than every temperature measured in the unit "
                                   "(the coldest 12.1 °C, at sat): only a space that cold or a cold source explains them")
    assert caution(11.0, 0.63) == "" and caution(25.0, 0.1) == "" and caution(5.64, np.inf) == ""
