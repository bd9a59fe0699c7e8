"""Physics sanity checks of the reference plant: each could fail if the plant were wrong."""

from __future__ import annotations

import csv
import re
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from .csv_output import write_plant_csv
from .equipment import AIR_CP, AIR_DENSITY, WATER_CP, WATER_DENSITY, PlugFlowPipe
from .faults import FAULTS, Fault
from .plant import PlantRun, simulate_plant

DAY_S = 86400.0
CASE_STUDY = Path(__file__).resolve().parents[2] / "service" / "examples" / "ventilation_case_study" / "model.ttl"


@cache
def run(fault: str | None = None, size: float = 0.0, start_day: float = 0.0, seed: int = 3) -> PlantRun:
    injected = Fault(name=fault, size=size, start_s=start_day * DAY_S) if fault else None
    return simulate_plant(days=7.0, seed=seed, fault=injected)


def _after(r: PlantRun, day: float) -> np.ndarray:
    return r.timestamps >= r.timestamps[0] + np.timedelta64(int(day * DAY_S), "s")


def test_air_side_and_water_side_heat_balance_within_noise():
    r = run()
    hidden, readings = r.hidden, r.readings
    assert abs(hidden["coil_air_heat_w"].sum() - hidden["coil_water_heat_w"].sum()) < 0.01 * hidden["coil_water_heat_w"].sum()
    heating = hidden["water_flow_m3_s"] > 0.02e-3  # the measured side: steps with water flowing
    air = (AIR_DENSITY * AIR_CP * readings["supply_air_flow"]
           * (readings["coil_outlet_air_temperature"] - readings["fan_inlet_air_temperature"]) - hidden["fan_heat_w"])
    water = (WATER_DENSITY * WATER_CP * hidden["water_flow_m3_s"]
             * (readings["coil_inlet_water_temperature"] - readings["coil_outlet_water_temperature"]))
    assert heating.sum() > 200
    assert air[heating].sum() == pytest.approx(water[heating].sum(), rel=0.06)


def test_a_leak_heats_the_air_with_command_and_position_at_zero():
    leaking, tight = run("valve_leakage", 0.05, start_day=2.0), run()
    shut = (_after(leaking, 2.0) & (leaking.readings["valve_position"] == 0.0)
            & (leaking.hidden["command"] == 0.0))
    assert shut.sum() > 100
    assert leaking.hidden["coil_air_heat_w"][shut].mean() > 500.0
    tight_shut = (tight.readings["valve_position"] == 0.0) & (tight.hidden["command"] == 0.0)
    assert tight.hidden["coil_air_heat_w"][tight_shut].mean() < 50.0


def test_a_stuck_valve_ignores_its_command_and_its_position_reads_the_stem():
    stuck = run("valve_stuck", 0.25, start_day=1.0)
    after = _after(stuck, 1.0)
    assert np.abs(stuck.readings["valve_position"][after] - 0.25).max() < 0.02
    assert stuck.hidden["command"][after].std() > 0.1  # the controller winds up and down: ignored
    before = ~after & _after(stuck, 0.1)
    assert np.abs(stuck.readings["valve_position"][before] - stuck.hidden["command"][before]).mean() < 0.03


def test_transport_delay_is_water_content_over_flow():
    volume, dt = 6e-3, 1.0
    arrivals = {}
    for flow in (0.3e-3, 0.02e-3):
        pipe = PlugFlowPipe(volume, 0.0, 15.0, 4000, dt, initial_c=20.0)
        outlet = np.array([pipe.step(60.0, flow) for _ in range(4000)])
        arrivals[flow] = (np.argmax(outlet > 40.0) + 1) * dt
    assert arrivals[0.3e-3] == pytest.approx(volume / 0.3e-3, abs=2 * dt)
    assert arrivals[0.02e-3] == pytest.approx(volume / 0.02e-3, abs=2 * dt)


def test_stagnant_water_cools_towards_the_plant_room():
    pipe = PlugFlowPipe(6e-3, 2.0, 15.0, 30000, 1.0, initial_c=55.0)
    outlet = [pipe.step(55.0, 0.0) for _ in range(30000)]
    assert outlet[0] > 54.9 and 15.0 < outlet[-1] < 30.0


def test_fan_power_rises_with_about_the_cube_of_the_flow():
    r = run()
    flow, power = r.readings["supply_air_flow"], r.readings["supply_fan_power"]
    slope = np.polyfit(np.log(flow), np.log(power), 1)[0]
    assert 2.1 < slope < 3.1


def test_weekend_setback_and_reduced_weekend_flow_are_visible():
    r = run()  # from Thursday 2026-01-15
    weekday = (r.timestamps.astype("datetime64[D]").astype(int) - 4) % 7
    hour = (r.timestamps - r.timestamps.astype("datetime64[D]")).astype(int) / 3600.0
    weekend = weekday >= 5
    occupied = ~weekend & (hour >= 8) & (hour < 18)
    setpoint, air = r.readings["coil_outlet_air_temperature_setpoint"], r.readings["coil_outlet_air_temperature"]
    assert np.all(setpoint[weekend] == 16.0) and np.all(setpoint[occupied] == 20.0)
    assert air[occupied].mean() - air[weekend].mean() > 2.0
    assert r.readings["supply_air_flow"][weekend].mean() < 0.5 * r.readings["supply_air_flow"][occupied].mean()


def test_a_sensor_offset_moves_the_reading_and_the_controller_follows_it():
    r = run("sensor_offset", 1.5, start_day=1.0)
    after = _after(r, 1.5)
    bias = r.readings["coil_outlet_air_temperature"][after] - r.hidden["coil_outlet_air_c"][after]
    assert np.median(bias) == pytest.approx(1.5, abs=0.2)


def test_the_same_seed_gives_the_same_data_and_another_seed_other_data():
    a, b = simulate_plant(days=1.0, seed=5), simulate_plant(days=1.0, seed=5)
    c = simulate_plant(days=1.0, seed=6)
    for column in a.readings:
        np.testing.assert_array_equal(a.readings[column], b.readings[column])
    assert not np.array_equal(a.readings["coil_outlet_air_temperature"], c.readings["coil_outlet_air_temperature"])


def test_the_csv_holds_every_series_the_case_study_names_and_the_truth_is_apart(tmp_path):
    path = tmp_path / "plant.csv"
    truth = write_plant_csv(path, fault="valve_stuck", size=0.4, fault_start="2026-01-16T06:00", days=2.0, seed=1)
    with open(path, encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    series_ids = set(re.findall(r'gt:timeSeriesId "([^"]+)"', CASE_STUDY.read_text(encoding="utf-8")))
    assert rows[0][0] == "timestamp" and set(rows[0][1:]) == series_ids
    assert len(rows) == 1 + 2 * 144 and rows[1][0] == "2026-01-15 00:00:00" and rows[2][0] == "2026-01-15 00:10:00"
    assert (truth.fault, truth.size, truth.node, truth.catalog_effect) == ("valve_stuck", 0.4, "heating_valve", "valve stuck")
    assert str(truth.start) == "2026-01-16T06:00:00"
    assert all(kind.node in CASE_STUDY.read_text(encoding="utf-8") for kind in FAULTS.values())
