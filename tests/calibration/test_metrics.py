"""Metrics against hand-computed values (n − p, the sign of NMBE, coverage, applicability)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from service.calibration.metrics import target_metrics

OBSERVED = np.array([10.0, 12.0, np.nan, 14.0, 16.0])
PREDICTED = np.array([9.0, 11.0, 0.0, 13.0, 17.0])  # errors y − ŷ at the measured steps: 1, 1, 1, −1


def test_hand_computed_values_with_n_minus_p():
    m = target_metrics(OBSERVED, PREDICTED, n_parameters=1, unit="W", target="fan power")
    # n = 4 measured, p = 1, ȳ = 13, Σe = 2, Σe² = 4, Σ(y − ȳ)² = 20
    assert m.n == 4 and m.mean_observed == 13.0
    assert m.rmse == pytest.approx(1.0)
    assert m.mae == pytest.approx(1.0)
    assert m.r2 == pytest.approx(0.8)
    assert m.cv_rmse_percent == pytest.approx(np.sqrt(4 / 3) / 13 * 100, rel=1e-12)  # 8.882 %
    assert m.nmbe_percent == pytest.approx(2 / (3 * 13) * 100, rel=1e-12)  # +5.128 %: under-prediction
    assert m.guideline14_applies and m.guideline14_pass is True
    # residual lag 1: centred (0.5, 0.5, ·, 0.5, −1.5); only the pairs (0, 1) and (3, 4) are measured
    assert m.lag1_autocorrelation == pytest.approx((0.25 - 0.75) / 3.0)


def test_over_prediction_gives_a_negative_nmbe():
    m = target_metrics(OBSERVED, np.where(np.isnan(OBSERVED), 0.0, OBSERVED + 2.0), n_parameters=2, unit="W")
    assert m.nmbe_percent == pytest.approx(-2.0 * 4 / (2 * 13) * 100)  # −30.8 %
    assert m.guideline14_applies and m.guideline14_pass is False


def test_a_negative_mean_neither_passes_guideline14_by_sign_nor_flips_nmbe():
    # a cooling coil's heat rate: mean −13 W; the same errors as above, mirrored
    m = target_metrics(-OBSERVED, -PREDICTED, n_parameters=1, unit="W")
    assert m.cv_rmse_percent == pytest.approx(np.sqrt(4 / 3) / 13 * 100, rel=1e-12)
    assert m.nmbe_percent == pytest.approx(-2 / (3 * 13) * 100, rel=1e-12)  # the model over-predicts
    scattered = target_metrics(-OBSERVED, -OBSERVED + np.array([8.0, -8.0, 0.0, 8.0, -8.0]), unit="W")
    assert scattered.cv_rmse_percent > 30 and scattered.guideline14_pass is False


def test_interval_coverage_and_average_coverage_error():
    intervals = {0.9: (PREDICTED - 1.5, PREDICTED + 1.5), 0.5: (PREDICTED - 0.5, PREDICTED + 1.2)}
    m = target_metrics(OBSERVED, PREDICTED, intervals=intervals)
    by_level = {c.level: c for c in m.coverage}
    assert by_level[0.9].coverage == 1.0 and by_level[0.9].ace == pytest.approx(0.1)
    assert by_level[0.9].mean_width == pytest.approx(3.0)
    # errors 1, 1, 1 lie in [−0.5, 1.2], −1 does not → 3/4
    assert by_level[0.5].coverage == 0.75 and by_level[0.5].ace == pytest.approx(0.25)
    assert by_level[0.5].mean_width == pytest.approx(1.7)


def test_guideline14_is_not_applied_where_the_mean_is_meaningless():
    celsius = target_metrics(OBSERVED, PREDICTED, unit="degC")
    assert not celsius.guideline14_applies and celsius.guideline14_pass is None
    assert "zero of the scale" in celsius.guideline14_note
    assert np.isfinite(celsius.cv_rmse_percent)  # still reported
    alternating = np.array([-1.0, 1.0, -1.0, 1.1])
    near_zero = target_metrics(alternating, np.zeros(4), unit="W")
    assert not near_zero.guideline14_applies and "near zero" in near_zero.guideline14_note
    # a mean within the noise of zero (a valve that stays shut, read by a walkthrough as CV(RMSE) 178 %)
    assert np.isnan(near_zero.cv_rmse_percent) and np.isnan(near_zero.nmbe_percent)
    too_few = target_metrics(OBSERVED, PREDICTED, n_parameters=4, unit="W")
    assert not too_few.guideline14_applies and np.isnan(too_few.cv_rmse_percent) and np.isnan(too_few.nmbe_percent)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="target valve: prediction is not finite at row 1"):
        target_metrics(OBSERVED, np.array([1.0, np.nan, 1.0, 1.0, 1.0]), target="valve")
    with pytest.raises(ValueError, match="no measured step"):
        target_metrics(np.full(3, np.nan), np.zeros(3))
    with pytest.raises(ValueError, match=r"interval 0.9: bounds of shape \(2,\)"):
        target_metrics(OBSERVED, PREDICTED, intervals={0.9: (np.zeros(2), np.ones(2))})


def test_to_dict_is_json_ready():
    m = target_metrics(OBSERVED, PREDICTED, intervals={0.9: (PREDICTED - 2, PREDICTED + 2)}, unit="W", target="p")
    data = json.loads(json.dumps(m.to_dict()))
    assert data["coverage"][0]["level"] == 0.9 and data["target"] == "p" and data["n"] == 4


def test_the_noise_the_residual_shows_is_reported_beside_the_rmse():
    """White noise of 0.3 K on a slow model error: σ from the residual's second differences (the slow
    error hardly moves them), while the RMSE carries both; a gap in the data is no noise."""
    rng = np.random.default_rng(3)
    t = np.arange(1008)
    truth = 20.0 + 2.0 * np.sin(2 * np.pi * t / 144)
    observed = truth + rng.normal(0.0, 0.3, t.size)
    observed[500:520] = np.nan
    metrics = target_metrics(observed, truth + 0.5 * np.sin(2 * np.pi * t / 1008), unit="degC")
    assert metrics.noise == pytest.approx(0.3, rel=0.15) and metrics.rmse > 1.2 * metrics.noise
    assert target_metrics(truth + 0.01, truth, unit="degC").noise == 0.1  # floored at the sensor's accuracy
    assert metrics.to_dict()["noise"] == metrics.noise
