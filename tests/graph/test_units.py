"""QUDT unit IRIs → simulator port units: hand-computed conversions, differences, clear errors."""

import numpy as np
import pytest

from service.graph.units import QUDT_UNITS, UnitError, closest_unit_hint, convert, unit_label

U = "http://qudt.org/vocab/unit/"


@pytest.mark.parametrize(("value", "unit", "port", "expected"), [
    (32.0, "DEG_F", "degC", 0.0),
    (212.0, "DEG_F", "degC", 100.0),
    (-40.0, "DEG_F", "degC", -40.0),
    (293.15, "K", "degC", 20.0),
    (20.0, "DEG_C", "degC", 20.0),
    (50.0, "PERCENT", "1", 0.5),
    (3600.0, "M3-PER-HR", "m3/s", 1.0),
    (250.0, "L-PER-SEC", "m3/h", 900.0),  # 0.25 m³/s · 3600 s/h
    (1000.0, "FT3-PER-MIN", "m3/s", 0.47194745),  # 1 cfm = 0.3048³ m³ / 60 s
    (3600.0, "KiloGM-PER-HR", "kg/s", 1.0),
    (1.5, "KiloW", "W", 1500.0),
    (1000.0, "BTU_IT-PER-HR", "W", 293.07107),
    (100.0, "KiloPA", "bar", 1.0),
    (2.0, "IN_H2O", "Pa", 498.17782),  # 1 inH₂O (4 °C) = 249.08891 Pa
    (3.0, "MIN", "s", 180.0),
    (2.0, "HR", "s", 7200.0),
    (0.8, "KiloW-PER-K", "W/K", 800.0),
])
def test_qudt_units_convert_to_port_units(value, unit, port, expected):
    assert convert([value], U + unit, port) == pytest.approx([expected], rel=1e-9, abs=1e-12)


def test_temperature_differences_drop_the_offset():
    # port unit "K" is a difference: a 9 °F bias is 5 K, a 3 °C rise is 3 K
    assert convert([9.0, -1.8], U + "DEG_F", "K") == pytest.approx([5.0, -1.0])
    assert convert([3.0], U + "DEG_C", "K") == pytest.approx([3.0])
    assert convert([5.0], "K", U + "DEG_F") == pytest.approx([9.0])
    # the QUDT IRI unit:K stays absolute
    assert convert([273.15], U + "K", "degC") == pytest.approx([0.0], abs=1e-12)


def test_an_error_of_readings_logged_in_another_unit_is_stated_in_both():
    """A diagnosis of °F data states its errors in K, the model's unit, and in °F, the column's: the
    difference scales by the multipliers alone (14.5 K is 26.1 °F, not 58.1 °F)."""
    from service.graph.units import difference_text

    assert difference_text(14.5, "degC", U + "DEG_F") == "14.5 K (26.1 °F)"
    assert difference_text(14.5, "degC") == difference_text(14.5, "degC", U + "DEG_C") == "14.5 K"
    assert difference_text(250.0, "W", U + "KiloW") == "250 W (0.25 kW)"
    assert difference_text(0.02, "1", U + "PERCENT") == "0.02 (2 %)"
    assert difference_text(float("nan"), "degC", U + "DEG_F") == "–"
    assert difference_text(2.0, "degC", U + "KiloGM-PER-SEC") == "2 K"  # another dimension: not restated


def test_conversion_is_affine_keeps_shape_and_round_trips():
    values = np.array([[14.0, 68.0], [95.0, np.nan]])
    celsius = convert(values, U + "DEG_F", "degC")
    assert celsius.shape == (2, 2) and np.isnan(celsius[1, 1])
    assert celsius[0] == pytest.approx([-10.0, 20.0])
    np.testing.assert_allclose(convert(celsius, "degC", U + "DEG_F"), values, rtol=1e-12)
    assert convert([1.0], "DEG_F", "degC") == pytest.approx(convert([1.0], U + "DEG_F", "degC"))  # local name


def test_incompatible_and_unknown_units_are_named_with_the_port():
    with pytest.raises(UnitError, match=r"DEG_F \(temperature\) to kg/s \(mass_flow\) for port fan\.outlet_air_mass_flow"):
        convert([1.0], U + "DEG_F", "kg/s", where="port fan.outlet_air_mass_flow")
    with pytest.raises(UnitError, match=r"unknown unit '.*FURLONG' for column 'speed':.*DEG_F") as graphs:
        convert([1.0], U + "FURLONG", "m3/s", where="column 'speed'")
    assert "port units" not in str(graphs.value)  # a graph's unit: the simulator's port units would only confuse
    with pytest.raises(UnitError, match="unknown unit 'furlong/s'.* and the port units .*degC"):
        convert([1.0], U + "M3-PER-SEC", "furlong/s")
    with pytest.raises(UnitError, match=r"1/K \(inverse_temperature\) to K \(temperature\)"):
        convert([1.0], "1/K", "K")


def test_an_unknown_unit_is_matched_to_a_known_one_only_up_to_case_and_separators():
    """``DEGC`` and ``deg_c`` are DEG_C; a name merely close to a known one is often another scale or
    dimension (litres an hour, a kilowatt hour): no guess."""
    assert closest_unit_hint(U + "DEGC") == closest_unit_hint(U + "deg_c") == f" (did you mean {U}DEG_C?)"
    assert closest_unit_hint(U + "kilow") == f" (did you mean {U}KiloW?)"
    # a letter added or two swapped is a slip; a letter replaced is often another scale
    assert closest_unit_hint(U + "DEG_CC") == f" (did you mean {U}DEG_C?)"
    assert closest_unit_hint(U + "M3-PER-SCE") == f" (did you mean {U}M3-PER-SEC?)"
    assert closest_unit_hint(U + "DEG_G") == closest_unit_hint(U + "WW") == ""
    for unknown in ("L-PER-HR", "KiloW-HR", "M3-PER-MIN", "KiloGM-PER-MIN", "DEG_K", "FURLONG"):
        assert closest_unit_hint(U + unknown) == "", unknown
    with pytest.raises(UnitError, match=r"unknown unit '.*DEGC' for column 'T' \(did you mean .*DEG_C\?\)"):
        convert([1.0], U + "DEGC", "degC", where="column 'T'")


def test_labels_for_reports():
    assert unit_label(U + "DEG_F") == "°F" and unit_label("m3/s") == "m³/s"
    assert unit_label(U + "FURLONG") == U + "FURLONG"
    assert all(spec.multiplier > 0 for spec in QUDT_UNITS.values())


def test_a_plain_number_has_no_unit_label_in_reports():
    """A valve position (the fraction '1') printed as '0.0194 1' and plotted over '[1]'."""
    from service.graph.units import bracketed_unit, unit_label

    assert (unit_label("1"), bracketed_unit("1")) == ("", "")
    assert (unit_label("degC"), bracketed_unit("degC"), unit_label("%"), unit_label("1/K")) == ("°C", "[°C]", "%", "1/K")


def test_a_quantity_in_a_sentence_or_a_table_cell():
    """One formatter for the CLI, the report page and the diagnosis's sentences."""
    from service.graph.units import quantity_text

    assert quantity_text(0.16234, "degC") == "0.162 °C" and quantity_text(0.0194, "1") == "0.0194"
    assert quantity_text(5000.0, "W", "g") == "5000 W" and quantity_text(5000.0, "W") == "5e+03 W"
    assert quantity_text(float("nan"), "W") == quantity_text(None, "degC") == "–"


def test_an_error_of_a_temperature_in_celsius_is_stated_in_kelvin():
    """An RMSE, a residual or a noise σ is a difference: 0.2 K, not 0.2 °C; other units keep theirs."""
    from service.graph.units import difference_unit, quantity_text

    assert [unit_label(difference_unit(u)) for u in ("degC", U + "DEG_C", "K", U + "DEG_F", "W", "1")] == [
        "K", "K", "K", "°F", "W", ""]
    assert quantity_text(0.2, difference_unit("degC")) == "0.2 K"
    assert difference_unit(U + "FURLONG") == U + "FURLONG"
