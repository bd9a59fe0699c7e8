"""The page speaks to an engineer: evidence in words with the numbers one click away, p-values that
mean something, units only where there are units, and figure legends that never cover data."""

import re

import numpy as np
import pytest
from test_report_page import PageParser, report_page

from service.diagnosis.error_history import ErrorHistory
from service.report.page import SOME_EVIDENCE_DELTA_BIC, evidence_words, p_value_text
from service.report.plots import error_history_figure, measured_vs_model_figure, residuals_figure
from service.report.stored_run import StoredCandidate

X = "https://example.org/ahu#"


def candidate(significant: bool, delta_bic: float, test_improvement: float) -> StoredCandidate:
    return StoredCandidate(effect="ValveLeakage", label="Valve leakage", node=X + "valve", rank=1,
                           significant=significant, explanation="", score=3.0, p_value=0.08, delta_bic=delta_bic,
                           test_improvement=test_improvement)


@pytest.mark.parametrize("significant, delta_bic, improvement, words", [
    (True, -1776.0, 0.35, "clear evidence"),  # the diagnosis's significance: ΔBIC < −10 and ≥ 20 % removed
    (False, -7.8, 0.12, "some evidence"),  # the FLEXLAB leak day: short of −10, some error removed
    (False, SOME_EVIDENCE_DELTA_BIC - 0.1, 0.01, "some evidence"),
    (False, -7.8, 0.0, "no evidence"),  # removes nothing out of sample
    (False, 6.8, 0.30, "no evidence"),  # the refit is not worth its parameters
    (False, float("nan"), float("nan"), "no evidence"),  # not refitted
])
def test_the_evidence_words_follow_the_diagnosis_statistics(significant, delta_bic, improvement, words):
    assert evidence_words(candidate(significant, delta_bic, improvement)) == words


def test_p_values_below_one_in_a_million_are_not_printed_as_digits():
    assert p_value_text(1e-278) == "< 10⁻⁶" and p_value_text(0.0) == "< 10⁻⁶"
    assert p_value_text(2.3e-6) == "2.3e-06" and p_value_text(0.0412) == "0.041" and p_value_text(1.0) == "1"
    assert p_value_text(float("nan")) == "–"


def test_a_plain_number_has_no_unit_and_no_stray_space(tmp_path_factory):
    page = report_page(tmp_path_factory.getbasetemp() / "report-run")
    assert not re.search(r"\d </td>", page) and " [1]" not in page and "0.0194 1" not in page
    header, *rows = PageParser(page).tables["regimes"]
    valve, air = header.index("RMSE valve_position_sensor"), header.index("RMSE coil_outlet_air_temperature_sensor")
    assert all(re.fullmatch(r"[0-9.e-]+", row[valve]) for row in rows)  # the valve position is a fraction
    assert all(re.fullmatch(r"[0-9.e-]+ K", row[air]) for row in rows)


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _assert_legends_outside_every_axes(fig) -> None:
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend() is not None)]
    assert legends
    for legend in legends:
        box = legend.get_window_extent(renderer)
        assert box.x0 >= -1 and box.y0 >= -1 and box.x1 <= fig.bbox.x1 + 1 and box.y1 <= fig.bbox.y1 + 1  # shown
        for ax in fig.axes:
            assert not _overlaps(box, ax.get_window_extent(renderer)), (legend.get_texts()[0].get_text(),
                                                                        ax.get_title())


def test_figure_legends_sit_outside_the_data():
    t = np.arange("2026-01-13T00:00", "2026-01-14T00:00", 600, dtype="datetime64[s]")
    y = {X + "supply_air_temperature_sensor": 20 + np.sin(np.arange(t.size) / 20),
         X + "valve_position_sensor": 0.5 + 0.1 * np.cos(np.arange(t.size) / 9)}
    units = {X + "supply_air_temperature_sensor": "http://qudt.org/vocab/unit/DEG_C",
             X + "valve_position_sensor": "http://qudt.org/vocab/unit/UNITLESS"}
    band = {k: (v - 0.2, v + 0.2) for k, v in y.items()}
    _assert_legends_outside_every_axes(measured_vs_model_figure(
        t, y, {"model": y, "with the effect": y}, units, band, title="test window", interval_label="posterior 5–95 %"))
    episodes = {X + "valve_position_sensor": [(t[5], t[40])]}
    _assert_legends_outside_every_axes(residuals_figure(t, {k: v - v.mean() for k, v in y.items()}, units,
                                                        {k: 0.3 for k in y}, episodes))
    sensors = list(y)
    history = ErrorHistory(versions=["case", "case+ValveLeakage"], rmse={s: [1.0, 0.1] for s in sensors},
                           units=units, regime_rmse={"a ≤ 1": {s: [1.0, 0.2] for s in sensors},
                                                     "a > 1": {s: [0.8, 0.1] for s in sensors}},
                           regime_share={}, tested_on=["x", "x"])
    _assert_legends_outside_every_axes(error_history_figure(history))
