"""Operating regimes on synthetic operation generated from known rules."""

import numpy as np
import pytest

from service.calibration.regimes import OperatingRegimes, RuleCondition, per_regime_metrics, smoothed_rate, worst_regime

NAMES = ["supply fan speed", "heating valve position", "cooling valve position", "outdoor air temperature"]
UNITS = ["1", "1", "1", "°C"]
#: The generating rules: fan off (speed 0) / on (0.6–0.9); a valve shut (0) / open (0.4–1.0). The
#: clusters meet in the middle of those gaps, so these are the true thresholds.
FAN_THRESHOLD = 0.3
VALVE_THRESHOLD = 0.2


def three_regime_operation(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """16 blocks of 150–350 ten-minute steps: 0 = fan off, 1 = fan on heating, 2 = fan on cooling.

    Within a block the commands fluctuate uniformly over their range (a modulating controller),
    plus sensor noise; the outdoor temperature is a daily swing shared by all regimes (a distractor).
    """
    rng = np.random.default_rng(seed)
    blocks, truth, t0 = [], [], 0
    for regime in np.resize([0, 1, 0, 2, 0, 1], 16):
        n = int(rng.integers(150, 350))
        t = np.arange(t0, t0 + n)
        t0 += n
        swing = rng.uniform(-1.0, 1.0, n)
        fan = np.zeros(n) if regime == 0 else 0.75 + 0.15 * swing
        heating = 0.7 + 0.3 * swing if regime == 1 else np.zeros(n)
        cooling = 0.7 + 0.3 * swing if regime == 2 else np.zeros(n)
        outdoor = 15.0 + 8.0 * np.sin(2 * np.pi * t / 144.0)
        noise = rng.normal(0.0, [0.005, 0.005, 0.005, 0.2], size=(n, 4))
        blocks.append(np.column_stack([fan, heating, cooling, outdoor]) + noise)
        truth.append(np.full(n, regime))
    return np.vstack(blocks), np.concatenate(truth)


@pytest.fixture(scope="module")
def operation():
    return three_regime_operation(seed=1)


@pytest.fixture(scope="module")
def fitted(operation):
    features, _ = operation
    return OperatingRegimes(max_regimes=6, random_state=0).fit(features, NAMES, feature_units=UNITS, step_s=600.0)


def _agreement(labels: np.ndarray, truth: np.ndarray) -> float:
    """Share of steps whose regime maps to the true regime by majority (1.0: same partition)."""
    hits = sum(np.bincount(truth[labels == r]).max() for r in np.unique(labels))
    return hits / len(truth)


def test_silhouette_criterion_finds_the_three_regimes(fitted, operation):
    _, truth = operation
    assert fitted.n_regimes_ == 3
    assert max(fitted.selection_scores_, key=fitted.selection_scores_.get) == 3
    assert sorted(fitted.selection_scores_) == [2, 3, 4, 5, 6]
    assert _agreement(fitted.labels_, truth) > 0.99
    # Regimes are numbered by decreasing share: fan off is half of the blocks.
    assert np.bincount(fitted.labels_).tolist() == sorted(np.bincount(fitted.labels_).tolist(), reverse=True)
    assert fitted.centers_[0, 0] == pytest.approx(0.0, abs=0.01)  # fan off, engineering units
    assert fitted.centers_[1:, 0] == pytest.approx([0.75, 0.75], abs=0.02)


def test_rules_name_the_generating_features_and_thresholds(fitted, operation):
    features, truth = operation
    assert fitted.rule_accuracy_ > 0.9
    off = int(np.bincount(fitted.labels_[truth == 0]).argmax())
    heating = int(np.bincount(fitted.labels_[truth == 1]).argmax())
    cooling = int(np.bincount(fitted.labels_[truth == 2]).argmax())
    [[off_condition]] = fitted.rule_conditions_[off]
    assert off_condition.signal == "supply fan speed" and off_condition.lower is None
    assert off_condition.upper == pytest.approx(FAN_THRESHOLD, rel=0.1)
    assert fitted.rules_[off] == f"supply fan speed ≤ {round(off_condition.upper, 2):g}"
    for regime, open_valve in ((heating, "heating valve position"), (cooling, "cooling valve position")):
        [conditions] = fitted.rule_conditions_[regime]
        by_signal = {c.signal: c for c in conditions}
        assert by_signal["supply fan speed"].lower == pytest.approx(FAN_THRESHOLD, rel=0.1)
        valve = [c for c in conditions if "valve" in c.signal]
        assert len(valve) == 1 and not valve[0].is_rate
        threshold = valve[0].lower if valve[0].signal == open_valve else valve[0].upper
        assert threshold == pytest.approx(VALVE_THRESHOLD, rel=0.1)
        assert "outdoor air temperature" not in fitted.rules_[regime]
    # The tree is what predict applies: on the training data it reproduces the clusters.
    assert np.mean(fitted.predict(features) == fitted.labels_) > 0.99


def test_seeded_fits_give_the_same_labels(operation):
    features, _ = operation
    runs = [OperatingRegimes(max_regimes=4, random_state=7).fit(features, NAMES).labels_ for _ in range(2)]
    np.testing.assert_array_equal(*runs)


def test_predict_maps_a_new_window_and_marks_nan_steps(fitted):
    features, truth = three_regime_operation(seed=5)
    features[100:103, 3] = np.nan
    labels = fitted.predict(features)
    # The 5-step average touches the gap from step 98 to 104, its central difference from 97 to 105.
    assert (labels[97:106] == -1).all()
    assert (labels >= 0).sum() == len(labels) - 9
    assert _agreement(labels[labels >= 0], truth[labels >= 0]) > 0.99


def test_ramps_separate_from_steady_states():
    """A setpoint that holds 10 °C, ramps up at 4 K/h, holds 26 °C, ramps down: four regimes."""
    day = np.concatenate([np.full(96, 10.0), np.linspace(10, 26, 48), np.full(96, 26.0), np.linspace(26, 10, 48)])
    setpoint = np.tile(day, 6) + np.random.default_rng(0).normal(0, 0.2, 6 * len(day))
    model = OperatingRegimes(smoothing_steps=25, random_state=0).fit(
        setpoint[:, None], ["supply air temperature setpoint"], feature_units=["°C"], step_s=300.0)
    assert model.n_regimes_ == 4
    assert model.feature_units_ == ["°C", "K/h"]
    rate_centres = sorted(model.centers_[:, 1])
    assert rate_centres[0] == pytest.approx(-4.0, abs=0.3) and rate_centres[-1] == pytest.approx(4.0, abs=0.3)
    rising = int(np.argmax(model.centers_[:, 1]))
    assert "rising faster than" in model.rules_[rising] and "K/h" in model.rules_[rising]


def test_rate_conditions_read_as_engineering_words():
    def condition(lower, upper):
        return RuleCondition(3, "outdoor air temperature", "K/h", True, lower, upper, range_decimals=2)

    assert condition(0.5, None).describe() == "outdoor air temperature rising faster than 0.5 K/h"
    assert condition(None, -1.234).describe() == "outdoor air temperature falling faster than 1.23 K/h"
    assert condition(None, 0.8).describe() == "outdoor air temperature not rising faster than 0.8 K/h"
    assert condition(0.001, None).describe() == "outdoor air temperature rising"
    level = RuleCondition(0, "supply air flow", "m³/s", False, 1.1234, 2.5, range_decimals=2)
    assert level.describe() == "supply air flow between 1.12 and 2.5 m³/s"


def test_smoothed_rate_of_a_ramp_and_around_a_gap():
    ramp = np.arange(20.0)[:, None] * 0.5  # 0.5 per 10-minute step = 3 per hour
    np.testing.assert_allclose(smoothed_rate(ramp, 5, step_s=600.0)[:, 0], 3.0)
    ramp[10, 0] = np.nan
    rates = smoothed_rate(ramp, 3)[:, 0]
    assert np.isnan(rates[8:13]).all() and np.isfinite(rates[:8]).all() and np.isfinite(rates[13:]).all()
    np.testing.assert_allclose(rates[:7], 0.5)
    with pytest.raises(ValueError, match="odd"):
        smoothed_rate(ramp, 4)


def test_bad_input_is_refused(operation):
    features, _ = operation
    with pytest.raises(ValueError, match=r"expected \(n_steps, 3\)"):
        OperatingRegimes().fit(features, NAMES[:3])
    with pytest.raises(TypeError, match="feature_units"):
        OperatingRegimes().fit(features, NAMES, UNITS)
    with pytest.raises(ValueError, match="too few"):
        OperatingRegimes().fit(features[:2], NAMES)


def test_per_regime_metrics_and_worst_regime():
    labels = np.array([0, 0, 0, 1, 1, -1, 2, 2])
    observed = np.array([1.0, 2.0, 3.0, 4.0, np.nan, 9.0, 0.0, 0.0])
    predicted = np.array([1.0, 2.0, 4.0, 6.0, 5.0, 0.0, 0.0, 0.0])
    rmse = {"rmse": lambda y, yhat: float(np.sqrt(np.mean((y - yhat) ** 2))),
            "bias": lambda y, yhat: float(np.mean(y - yhat))}
    rows = per_regime_metrics(labels, observed, predicted, rmse, n_regimes=4)
    assert [r["share"] for r in rows] == pytest.approx([3 / 7, 2 / 7, 2 / 7, 0.0])
    assert rows[0]["rmse"] == pytest.approx(np.sqrt(1 / 3)) and rows[0]["bias"] == pytest.approx(-1 / 3)
    assert rows[1]["n_measured"] == 1 and rows[1]["rmse"] == pytest.approx(2.0)
    assert np.isnan(rows[3]["rmse"])
    assert worst_regime(rows, "rmse")["regime"] == 1
    assert worst_regime(rows, "rmse", higher_is_worse=False)["regime"] == 2
    assert worst_regime(rows, "rmse", min_share=0.35)["regime"] == 0
    with pytest.raises(ValueError, match="share of time"):
        worst_regime(rows, "rmse", min_share=0.5)


def test_paths_to_one_regime_that_differ_in_adjacent_intervals_of_one_feature_are_one_rule():
    """A walkthrough's worst regime read '(fan ≤ 11% and oat ≤ 5 °C and water ≤ 29.2 °C) or (fan ≤
    11% and oat ≤ 5 °C and water > 29.2 °C)', which is 'fan ≤ 11% and oat ≤ 5 °C'; paths that
    differ in two features stay two."""
    from service.calibration.regimes import _merged_paths

    def condition(feature, lower, upper):
        return RuleCondition(feature=feature, signal="xyz"[feature], unit="", is_rate=False, lower=lower, upper=upper,
                             range_decimals=1)

    def path(**bounds):
        return [condition("xyz".index(k), *v) for k, v in sorted(bounds.items())]

    merged = _merged_paths([path(x=(None, 11.0), y=(None, 5.0), z=(None, 29.2)),
                            path(x=(None, 11.0), y=(None, 5.0), z=(29.2, None))], condition)
    assert OperatingRegimes._rule_text(merged) == "x ≤ 11 and y ≤ 5"
    three = _merged_paths([path(x=(None, 1.0)), path(x=(1.0, 2.0)), path(x=(2.0, None), y=(None, 0.0))], condition)
    assert OperatingRegimes._rule_text(three) == "x ≤ 2 or (x > 2 and y ≤ 0)"
    apart = [path(x=(None, 1.0), y=(None, 0.0)), path(x=(1.0, None), y=(0.0, None))]
    assert _merged_paths(apart, condition) == apart
