"""Residual dependence on synthetic residuals with a known cause."""

import numpy as np
import pytest

from service.diagnosis.residual_dependence import residual_dependence

N = 1500


def signals_and_residual(seed: int = 0):
    """residual(t) = 0.8·x(t − 3) + noise; y is an AR(1) distractor, z = x + 0.5·w repeats x."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=N)
    w = rng.normal(size=N)
    y = np.zeros(N)
    for t in range(1, N):
        y[t] = 0.9 * y[t - 1] + rng.normal()
    residual = np.full(N, np.nan)
    residual[3:] = 0.8 * x[:-3]
    residual += rng.normal(0.0, 0.3, N)
    return residual, {"y": y, "z": x + 0.5 * w, "x": x}


def test_the_driving_signal_ranks_first_at_its_lag():
    residual, signals = signals_and_residual()
    ranked = residual_dependence(residual, signals, max_lag_steps=6)
    first = ranked[0]
    assert (first.signal, first.lag_steps, first.rank) == ("x", 3, 1)
    # ρ = 0.8 / sqrt(0.8² + 0.3²) = 0.936 for unit-variance x; sampling error ~ 1/sqrt(N).
    assert first.correlation == pytest.approx(0.8 / np.hypot(0.8, 0.3), abs=0.02)
    assert first.n_steps == N - 3
    assert first.cumulative_r2 == pytest.approx(first.correlation ** 2, rel=1e-9)  # alone: R² = ρ²
    assert first.partial_correlation == pytest.approx(first.correlation, rel=1e-9)
    second = ranked[1]
    assert (second.signal, second.lag_steps) == ("z", 3)
    # z only repeats x: its correlation is sizeable, its partial correlation given x is not.
    assert abs(second.correlation) > 0.7 and abs(second.partial_correlation) < 0.1
    assert second.cumulative_r2 == pytest.approx(first.cumulative_r2, abs=0.005)
    assert abs(ranked[2].correlation) < 0.1
    assert first.describe(step_s=600.0).startswith("the residual follows x 30 min earlier (ρ = +0.9")
    assert "alone it explains 8" in first.describe()


def test_nan_steps_constant_and_short_signals_are_handled():
    residual, signals = signals_and_residual(1)
    signals["x"] = signals["x"].copy()
    signals["x"][200:400] = np.nan
    signals["setpoint"] = np.full(N, 21.0)
    signals["setpoint"][5] = np.nan
    signals["sparse"] = np.where(np.arange(N) < 10, 1.0 * np.arange(N), np.nan)
    ranked = residual_dependence(residual, signals, max_lag_steps=5)
    assert ranked[0].signal == "x" and ranked[0].lag_steps == 3 and ranked[0].n_steps == N - 3 - 200
    skipped = {d.signal: d.skipped_reason for d in ranked if d.skipped_reason is not None}
    # The residual is unknown in its first 3 steps: 7 of sparse's 10 values are usable.
    assert skipped == {"setpoint": "constant over the valid steps",
                       "sparse": "only 7 finite valid steps (fewer than 20)"}
    assert ranked[-1].describe() == "sparse: not ranked, only 7 finite valid steps (fewer than 20)"
    assert all(np.isfinite(d.correlation) for d in ranked[:3])


def test_valid_restricts_the_steps():
    residual, signals = signals_and_residual(2)
    second_half = np.arange(N) >= N // 2
    residual[second_half] = np.random.default_rng(9).normal(size=second_half.sum())  # x drives only the first half
    assert residual_dependence(residual, signals, valid=~second_half)[0].signal == "x"
    ranked = residual_dependence(residual, signals, valid=second_half)
    assert all(abs(d.correlation) < 0.15 for d in ranked)
    assert ranked[0].n_steps == second_half.sum()


def test_bad_input_is_refused():
    residual, signals = signals_and_residual()
    with pytest.raises(ValueError, match="signal 'x' has shape"):
        residual_dependence(residual, {"x": signals["x"][:-1]})
    with pytest.raises(ValueError, match="residual is constant"):
        residual_dependence(np.ones(N), signals)
    with pytest.raises(ValueError, match="valid has shape"):
        residual_dependence(residual, signals, valid=np.ones(3, dtype=bool))


def test_a_residual_the_first_signal_explains_whole_gets_no_partial_correlation_after_it():
    t = np.arange(200.0)
    first, second = np.sin(t / 10.0), np.cos(t / 7.0)
    ranked = residual_dependence(2.0 * first, {"first": first, "second": second}, max_lag_steps=0)
    assert ranked[0].signal == "first" and ranked[0].cumulative_r2 == pytest.approx(1.0)
    assert ranked[1].partial_correlation is None and "nan" not in ranked[1].describe()


def test_a_residual_s_trend_in_time_is_its_slope_per_day_with_the_share_it_explains():
    from service.diagnosis.residual_dependence import time_trend

    rng = np.random.default_rng(1)
    stamps = np.datetime64("2026-01-14T00:00") + np.arange(432) * np.timedelta64(10, "m")  # 3 days
    days = np.arange(432) / 144.0
    trend = time_trend(0.4 * days + rng.normal(0.0, 0.1, 432), stamps)
    assert abs(trend.per_day - 0.4) < 0.02 and trend.r2 > 0.9  # var of the line 0.4²·0.75 against 0.01 of noise
    assert trend.describe("K").startswith("it drifts +0.4 K a day")
    flat = time_trend(rng.normal(0.0, 0.1, 432), stamps)
    assert flat.r2 < 0.05 and flat.describe("K").startswith("it has no trend in time")
    assert time_trend(np.full(432, 1.0), stamps) is None


def test_when_nothing_explains_a_failure_the_summary_describes_its_residual():
    from service.diagnosis.report import DiagnosisReport, SensorVerdict
    from service.diagnosis.residual_dependence import Dependence, TimeTrend

    node = "urn:x#coil_outlet_water_temperature_sensor"
    verdict = SensorVerdict(rmse=0.8, mae=0.6, cv_rmse_percent=3.0, nmbe_percent=1.0, r2=0.9, unit="degC",
                            noise=0.1, fails=True)
    regimes = [{"regime": 0, "rule": "fan speed ≤ 0.5", "share": 0.4, "rmse": {node: 0.3}},
               {"regime": 1, "rule": "fan speed > 0.5", "share": 0.6, "rmse": {node: 1.1}}]
    report = DiagnosisReport(
        model_name="m", run_id="r", sensors={node: verdict}, localization=[], regimes=regimes,
        regime_rule_accuracy=1.0, episodes={}, effects=[], not_applicable=[], step_s=600.0,
        residual_dependence={node: [Dependence("measured outdoor_temperature", 3, 0.81, 400, 0.81, 0.66, 1)]},
        residual_trend={node: TimeTrend(0.31, 0.64, 400)})
    summary = report.summary
    assert "no effect in the catalog and no drift of a parameter explains it" in summary
    assert "At coil_outlet_water_temperature_sensor, the worst (RMSE 0.8 K, 8.0× its noise)" in summary
    assert "it drifts +0.31 K a day (the trend explains 64 % of its variance)" in summary
    assert "its error is largest where fan speed > 0.5 (RMSE 1.1 K over 60 % of the test window)" in summary
    assert "it follows measured outdoor_temperature 30 min earlier (ρ = +0.81" in summary
    assert report.to_dict()["residual_trend"][node]["per_day"] == 0.31


def test_one_signal_under_two_names_is_ranked_once_the_first_name_kept():
    from service.diagnosis.residual_dependence import distinct_signals

    rng = np.random.default_rng(4)
    speed = rng.uniform(0.2, 1.0, 300)
    speed[5] = np.nan
    flow = 1.2 * 2.4 * speed + rng.normal(0, 0.005, 300)  # ρ ≈ 0.9999 with the speed
    other = rng.normal(size=300)
    kept = distinct_signals({"measured speed": speed, "model fan.measured_value": speed.copy(),
                             "model fan.outlet_air_mass_flow": flow, "measured outdoor": other,
                             "flat": np.ones(300)})
    assert list(kept) == ["measured speed", "measured outdoor", "flat"]
