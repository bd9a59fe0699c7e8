"""Failure episodes from injected excursions."""

import numpy as np
import pytest

from service.diagnosis.episodes import find_episodes

START = np.datetime64("2017-09-12T00:00")
STEP = np.timedelta64(10, "m")
N = 288  # two days of 10-minute steps
TIMESTAMPS = START + STEP * np.arange(N)


def noisy_residual(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 0.5, N)


def test_point_fit_excursions_are_found_with_their_spans():
    residual = noisy_residual()
    residual[37:112] += 16.0   # 06:10 – 18:40, measured above the model
    residual[200:210] -= 8.0   # a shorter excursion below
    residual[250] += 30.0      # a single-step spike: not an episode
    measured = 60.0 + residual
    episodes = find_episodes(TIMESTAMPS, measured, residual=residual, unit="°F")
    assert [(e.start, e.end) for e in episodes] == [
        (TIMESTAMPS[37], TIMESTAMPS[112]), (TIMESTAMPS[200], TIMESTAMPS[210])]
    first, second = episodes
    assert first.duration_h == pytest.approx(12.5) and first.n_steps == 75 and first.n_failing == 75
    assert first.peak_deviation == pytest.approx(residual[37:112].max())
    assert first.mean_deviation == pytest.approx(residual[37:112].mean())
    assert first.describe() == (f"2017-09-12 06:10 – 18:40 (12.5 h): measured above the model by up to "
                                f"{abs(first.peak_deviation):.3g} °F")
    assert second.peak_deviation < 0 and "below the model" in second.describe()
    # a column logged in °F, the model in °C: the size in K and, after it, in °F
    [logged, _] = find_episodes(TIMESTAMPS, measured, residual=residual / 1.8, unit="K",
                                logged_unit="http://qudt.org/vocab/unit/DEG_F")
    assert logged.describe().endswith(f"by up to {abs(first.peak_deviation) / 1.8:.3g} K "
                                      f"({abs(first.peak_deviation):.3g} °F)")
    assert logged.to_dict()["logged_unit"].endswith("DEG_F")
    assert second.describe().startswith("2017-09-13 09:20 – 11:00 (1.67 h)")


def test_runs_merge_across_short_gaps_and_nan_steps_never_fail():
    residual = np.random.default_rng(4).uniform(-0.1, 0.1, N)  # σ̂ ≈ 0.074: the limit 3σ̂ > 0.1
    residual[50:55] = 5.0
    residual[57:60] = 5.0  # two steps apart (≤ merge_gap_steps): one episode
    residual[100:104] = 5.0
    residual[107:111] = 5.0  # three steps apart: two episodes
    measured = residual.copy()
    measured[150:160] = np.nan
    residual[150:160] = 99.0  # not measured there: cannot fail
    episodes = find_episodes(TIMESTAMPS, measured, residual=residual)
    assert [(e.start, e.end, e.n_steps, e.n_failing) for e in episodes] == [
        (TIMESTAMPS[50], TIMESTAMPS[60], 10, 8),
        (TIMESTAMPS[100], TIMESTAMPS[104], 4, 4),
        (TIMESTAMPS[107], TIMESTAMPS[111], 4, 4),
    ]


def test_a_nan_gap_inside_an_excursion_is_bridged_when_short():
    residual = noisy_residual(1)
    residual[60:80] += 10.0
    measured = residual.copy()
    measured[69:71] = np.nan
    [episode] = find_episodes(TIMESTAMPS, measured, residual=residual)
    assert (episode.start, episode.end) == (TIMESTAMPS[60], TIMESTAMPS[80])
    assert episode.n_failing == 18


def test_prediction_interval_deviation_is_the_distance_beyond_the_bound():
    lower, upper = np.full(N, 20.0), np.full(N, 22.0)
    measured = np.full(N, 21.0)
    measured[10:20] = 25.0 + np.arange(10) * 0.1  # above: deviation 3.0 … 3.9
    measured[40:45] = [19.0, 23.0, 19.0, 23.0, 19.0]  # both sides
    measured[60:62] = 30.0  # two steps: shorter than min_duration_steps
    episodes = find_episodes(TIMESTAMPS, measured, lower, upper, unit="°C")
    assert len(episodes) == 2
    above, both = episodes
    assert above.peak_deviation == pytest.approx(3.9) and above.mean_deviation == pytest.approx(3.45)
    assert above.describe() == ("2017-09-12 01:40 – 03:20 (1.67 h): measured above the prediction interval "
                                "by up to 3.9 °C")
    assert both.both_sides and "on both sides of the prediction interval" in both.describe()


def test_min_deviation_floor_keeps_a_perfect_fit_quiet():
    residual = np.random.default_rng(2).normal(0.0, 0.01, N)  # quantisation-level noise
    residual[100:110] += 0.08  # 8 σ̂, but below the sensor accuracy
    assert find_episodes(TIMESTAMPS, residual, residual=residual)  # without a floor: an episode
    assert find_episodes(TIMESTAMPS, residual, residual=residual, min_deviation=0.2) == []


def test_an_episode_over_midnight_names_both_dates():
    residual = noisy_residual(3)
    residual[140:150] += 20.0
    [episode] = find_episodes(TIMESTAMPS, residual, residual=residual)
    assert episode.describe().startswith("2017-09-12 23:20 – 2017-09-13 01:00 (1.67 h)")


def test_bad_input_is_refused():
    residual = noisy_residual()
    with pytest.raises(ValueError, match="give both lower and upper"):
        find_episodes(TIMESTAMPS, residual, residual)  # a prediction passed where the lower bound goes
    with pytest.raises(ValueError, match="prediction interval .* or the residual"):
        find_episodes(TIMESTAMPS, residual)
    with pytest.raises(ValueError, match=r"residual has shape \(10,\)"):
        find_episodes(TIMESTAMPS, residual, residual=residual[:10])
    with pytest.raises(ValueError, match="strictly increasing"):
        find_episodes(TIMESTAMPS[::-1], residual, residual=residual)
