"""The diagnosis loop on real measured data: LBNL FLEXLAB X3A (SZVAV, September 2017, °F), faults imposed
by the experimenters (Granderson et al., Sci Data 7:65, 2020).

The base model (``flexlab_ahu``) is calibrated on the unfaulted 9/20 and diagnosed on the day of the
heating-coil valve leak (9/12, bypass open to 40 % of the valve's full flow) and on the day the
heating-coil valve was stuck fully open (9/14, the BMS logs the controller's demand, 0 all day). Both
faults put heat into the supply air with the valve commanded shut.

The data are 15-minute means of the 1-minute log: the static coil model does not resolve the coil's
minutes-long response, nor the controller's 9-minute hunting round the valve's dead band, and the
coarser step cuts the two diagnoses' cost fifteenfold (they remain the slowest test of the suite:
each calibrates the base model and fits every applicable catalog entry twice).
"""

import csv
import warnings
from pathlib import Path

import numpy as np
import pytest
from shared_data import SZVAV

from service.data.block_means import write_block_means
from service.diagnosis.loop import diagnose
from service.graph.store import GraphStore
from service.resources import examples_dir

EX = "https://example.org/flexlab-x3a#"
SUPPLY = EX + "supply_air_temperature_sensor"
HEATING = {EX + "heating_coil_valve", EX + "heating_coil"}
TRAIN = ("2017-09-20", "2017-09-20 23:59")
FAULT_DAYS = {"leak": "2017-09-12", "stuck_open": "2017-09-14"}
AVERAGE_MINUTES = 15

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not SZVAV.is_file(), reason=f"{SZVAV} is absent (the FLEXLAB data live in ../shared/realdata)"),
]


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    data = tmp_path_factory.mktemp("flexlab") / "szvav_15min.csv"
    write_block_means(SZVAV, data, AVERAGE_MINUTES, {TRAIN[0], *FAULT_DAYS.values()})
    out = {}
    for fault, day in FAULT_DAYS.items():
        store = GraphStore.embedded(None)
        store.load_model("flexlab", examples_dir() / "flexlab_ahu" / "model.ttl")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # unclaimed columns (set points, status, occupancy)
            report = diagnose(store, "flexlab", data, train=TRAIN, test=(day, f"{day} 23:59"), seed=0)
        out[fault] = {"report": report, "supply_air": _supply_air_celsius(data, day)}
    return out


def _supply_air_celsius(data: Path, day: str) -> np.ndarray:
    """The measured supply air temperature of ``day`` in the averaged file, °F → °C."""
    with data.open(newline="", encoding="utf-8") as handle:
        header, *rows = list(csv.reader(handle))
    column = [h.strip() for h in header].index("AHU: Supply Air Temperature")
    return np.array([(float(row[column]) - 32.0) / 1.8 for row in rows if row[0].startswith(day)])


@pytest.mark.parametrize("fault", sorted(FAULT_DAYS))
def test_the_model_fails_on_the_supply_air_temperature(reports, fault):
    """The base model calibrated on 9/20 misses the supply air by 10-20 K on the fault day, twenty
    times its mixed-air error. (The mixed air "fails" too, by 0.5-0.6 K against the small noise of
    15-minute means: its sensor reads up to 1.5 K above both return and outdoor air at the fan's
    minimum speed, which no mixing model reproduces; the localisation then treats the supply air's
    failure as inherited from it, so it names the mixing box, not the coils.)"""
    sensors = reports[fault]["report"].sensors
    supply, mixed = sensors[SUPPLY], sensors[EX + "mixed_air_temperature_sensor"]
    assert supply.fails and supply.rmse > 5.0, supply
    assert supply.rmse > 10.0 * mixed.rmse, (supply.rmse, mixed.rmse)
    # the columns are logged in °F, the model in °C: each error is said in K and in °F
    assert supply.logged_unit.endswith("DEG_F")
    episode = reports[fault]["report"].episodes[SUPPLY][0]
    assert episode.describe().endswith(f"K ({abs(episode.peak_deviation) * 1.8:.3g} °F)"), episode.describe()


@pytest.mark.parametrize("fault", sorted(FAULT_DAYS))
def test_the_top_effect_is_the_heating_valve_passing_water_while_shut(reports, fault):
    """The heating valve passing water while commanded shut ranks first (a leak, or a valve stuck a little
    open), fitted as a fault that
    appeared on the test day (null in training), with the heating coil's capacity, which the
    training day never exercised, fitted with it (the leak's size trades off against the coil's
    water flow and the actuator's dead band, which the training day did not identify either, so it
    is not asserted; a valve stuck fully open behind a logged command of 0 looks like a leak to a
    linear valve). The stuck valve (nested: stuck at s with weight w is a leak λ = w·s) is fitted
    with its host as trained: it finds a partial opening just past the coil's dead band and ranks
    lower. A constant heat gain at a coil (its air flow from the fan downstream in this draw-through
    unit) ranks close behind: with the valve shut all day, a leak differs from any heat source only
    in how it follows the air flow and the coil inlet temperature. Fan motor heat, a property of the
    fan and not a fault that appears from one day to the next, is not fitted as one. ΔBIC counts the
    host's five freed parameters and each sensor's effective sample size from the leak's own residuals
    (the base's, which hold the misfit it explains, left ~3 per sensor)."""
    effects = reports[fault]["report"].effects
    best = effects[0]
    # the two are nested (a leak is a valve stuck at λ with weight 1): on the 40 % leak they remove the same
    # 90 % of the held-out error, and since the fan's unmetered power curve is no longer fitted (2026-12-01)
    # the stuck valve's ΔBIC is the better one; the other is the next candidate
    assert best.effect in ("ValveLeakage", "ValveStuck") and best.node in HEATING, \
        [(e.effect, e.node, e.delta_bic, e.test_improvement) for e in effects[:3]]
    assert {effects[1].effect, best.effect} == {"ValveLeakage", "ValveStuck"} and effects[1].node in HEATING
    assert best.delta_bic < 0.0 and best.test_improvement >= 0.5, (best.delta_bic, best.test_improvement)
    fan_heat = next(e for e in effects if e.effect == "FanMotorHeat")
    assert "present throughout" in fan_heat.explanation and fan_heat.test_improvement < best.test_improvement


@pytest.mark.parametrize("fault", sorted(FAULT_DAYS))
def test_adding_it_at_least_halves_the_supply_air_error_on_data_it_was_not_fitted_on(reports, fault):
    """The evaluation half of the fault day (12:00–24:00): the model plus the top effect, fitted on
    the unfaulted day and the morning, against the base model as calibrated on the unfaulted day and
    against the base refitted on the same data as the effect."""
    report, observed = reports[fault]["report"], reports[fault]["supply_air"]
    best = report.effects[0]
    evaluation = slice(observed.size // 2, None)
    base = report.base_test_prediction[SUPPLY][evaluation]
    mask = np.isfinite(base) & np.isfinite(observed[evaluation])
    rmse_base = float(np.sqrt(np.mean((base[mask] - observed[evaluation][mask]) ** 2)))
    assert best.rmse_after[SUPPLY] <= 0.5 * rmse_base, (best.rmse_after[SUPPLY], rmse_base)
    assert best.rmse_after[SUPPLY] <= 0.5 * best.rmse_before[SUPPLY], (best.rmse_after, best.rmse_before)
