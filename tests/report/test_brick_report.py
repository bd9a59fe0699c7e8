"""service/report/brick.py: what the alignment did not use is listed, with what would be needed."""

import json

import pytest
from brick_report_model import REPORT_MODEL, REPORT_NAMESPACE
from shared_data import OFFICIAL_BRICK
from typer.testing import CliRunner

from service.cli import app
from service.graph.store import GraphStore
from service.report.brick import brick_report, official_brick_classes
from service.resources import examples_dir

BRICK = "https://brickschema.org/schema/Brick#"


def test_unaligned_classes_unread_relations_and_missing_links_are_listed():
    store = GraphStore.embedded(None)
    store.load_model("m", REPORT_MODEL.encode())
    report = brick_report(store, "m")
    by_class = {c.class_iri.removeprefix(BRICK): c for c in report.unaligned_classes}
    assert set(by_class) == {"Chiller", "Supply_Air_Temprature_Setpoint"}
    assert by_class["Chiller"].count == 1 and by_class["Chiller"].unaligned == 1
    assert "brick:Supply_Air_Temperature_Sensor" in by_class["Supply_Air_Temprature_Setpoint"].needed  # misspelt
    assert [(r.predicate.removeprefix(BRICK), r.count) for r in report.unread_relations] == [("regulates", 1)]
    sat = REPORT_NAMESPACE + "sat"
    assert report.points_without_unit == (sat,) and report.points_without_column == (sat,)


def test_a_saref_model_has_nothing_to_report():
    store = GraphStore.embedded(None)
    store.load_model("saref", examples_dir() / "flexlab_ahu" / "model.ttl")
    assert not brick_report(store, "saref").is_brick


def test_equipment_a_flow_edge_merely_passes_is_listed():
    """A humidifier between the mixing box and the cooling coil: brick:feeds through it becomes flow
    edges through it, but no rule models it — the report names it (before, the edges hid it)."""
    store = GraphStore.embedded(None)
    store.load_model("hum", b"""
@prefix brick: <https://brickschema.org/schema/Brick#> . @prefix ex: <http://example.org/> .
ex:ahu a brick:Air_Handling_Unit ; brick:hasPart ex:oad, ex:rad, ex:mix, ex:hum, ex:ccl, ex:sf ; brick:hasPoint ex:sat .
ex:oad a brick:Outside_Damper ; brick:feeds ex:mix . ex:rad a brick:Return_Damper ; brick:feeds ex:mix .
ex:mix a brick:HVAC_Equipment ; brick:feeds ex:hum .
ex:hum a brick:Humidifier ; brick:feeds ex:ccl . ex:ccl a brick:Cooling_Coil ; brick:feeds ex:sf .
ex:sf a brick:Supply_Fan ; brick:feeds ex:zone . ex:zone a brick:HVAC_Zone .
ex:sat a brick:Supply_Air_Temperature_Sensor .
""")
    by_class = {c.class_iri.removeprefix(BRICK): c for c in brick_report(store, "hum").unaligned_classes}
    assert set(by_class) == {"Humidifier"} and by_class["Humidifier"].unaligned == 1


def test_a_coils_leaving_water_point_is_listed_as_read_by_no_model_and_urn_iris_print_short(tmp_path):
    """A walkthrough's unit named its nodes with urn: IRIs (printed whole and cut mid-name at 80
    columns) and its heating coil's leaving water point was told to state the point's equipment,
    which it already did."""
    text = (examples_dir() / "flexlab_ahu_brick" / "model.ttl").read_text(encoding="utf-8").replace(
        "https://example.org/flexlab-x3a#", "urn:example:flexlab#") + """
ex:hw_entering a brick:Entering_Hot_Water_Temperature_Sensor ; brick:isPointOf ex:heating_coil ; brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "hw in" ] .
ex:hw_leaving a brick:Leaving_Hot_Water_Temperature_Sensor ; brick:isPointOf ex:heating_coil ; brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ a ref:TimeseriesReference ; ref:hasTimeseriesId "hw out" ] .
"""
    store = GraphStore.embedded(None)
    store.load_model("urn", text.encode())
    report = brick_report(store, "urn")
    assert report.water_points_unread == ("urn:example:flexlab#hw_leaving",)  # the entering one feeds the coil
    assert report.temperature_points_off_path == ()
    model = tmp_path / "urn.ttl"
    model.write_text(text, encoding="utf-8")
    result = CliRunner().invoke(app, ["brick-report", str(model), "--memory"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    flat = result.output.replace("│", "").replace("\n", "")
    assert "@prefix : <urn:example:flexlab#>" in " ".join(flat.split())  # said once, under the assumptions
    assert "urn:example:flexlab#outdoor" not in flat.replace(" ", "")  # nodes by their local names
    assert "Water temperature points no model reads" in result.output




@pytest.mark.skipif(not OFFICIAL_BRICK.is_file(), reason=f"the official Brick.ttl is not at {OFFICIAL_BRICK} (../shared)")
def test_the_official_ontology_tells_an_unmodelled_class_from_a_misspelt_one(tmp_path):
    """Without it a class outside graphtwin's subset might be either; with it, the chiller is official
    Brick graphtwin does not model, and the setpoint is no Brick class at all, with the official
    names close to it."""
    official = official_brick_classes(OFFICIAL_BRICK)
    assert BRICK + "Chiller" in official and BRICK + "Supply_Air_Temprature_Setpoint" not in official
    store = GraphStore.embedded(None)
    store.load_model("m", REPORT_MODEL.encode())
    by_class = {c.class_iri.removeprefix(BRICK): c.needed for c in brick_report(store, "m", official).unaligned_classes}
    assert by_class["Chiller"].startswith("official Brick, not in graphtwin's subset")
    misspelt = by_class["Supply_Air_Temprature_Setpoint"]
    assert misspelt.startswith("not official Brick")
    assert "Closest official classes: brick:Supply_Air_Temperature_Setpoint," in misspelt  # one graphtwin lacks
    model = tmp_path / "m.ttl"
    model.write_text(REPORT_MODEL)
    result = CliRunner().invoke(app, ["brick-report", str(model), "--memory", "--json", "--brick-ontology", str(OFFICIAL_BRICK)])
    assert result.exit_code == 0, result.output
    assert {c["class_iri"].removeprefix(BRICK): c["needed"] for c in json.loads(result.output)["unaligned_classes"]} == by_class


def test_a_file_that_is_not_the_brick_ontology_is_refused_naming_it(tmp_path):
    broken = tmp_path / "Brick.ttl"
    broken.write_text("@prefix brick: <https://brickschema.org/schema/Brick#> .\nbrick:Chiller a \n")
    with pytest.raises(ValueError, match=r"Brick.ttl, line 3, column \d+: "):
        official_brick_classes(broken)
    other = tmp_path / "other.ttl"
    other.write_text("<urn:a> a <http://www.w3.org/2002/07/owl#Class> .\n")
    with pytest.raises(ValueError, match="other.ttl: declares no Brick or RealEstateCore class"):
        official_brick_classes(other)
