"""service/brick_report.py: what the alignment did not use is listed, with what would be needed."""

from service.brick_report import brick_report
from service.resources import examples_dir
from service.store import GraphStore

BRICK = "https://brickschema.org/schema/Brick#"
MODEL = """
@prefix brick: <https://brickschema.org/schema/Brick#> .
@prefix unit:  <http://qudt.org/vocab/unit/> .
@prefix :      <https://example.org/report#> .
:ahu a brick:Air_Handling_Unit ; brick:hasPart :fan, :chiller ; brick:hasPoint :sat .
:fan a brick:Supply_Fan ; brick:regulates :sat .
:chiller a brick:Chiller .
:sat a brick:Supply_Air_Temperature_Sensor .
:sp a brick:Supply_Air_Temprature_Setpoint ; brick:isPointOf :ahu .
"""


def test_unaligned_classes_unread_relations_and_missing_links_are_listed():
    store = GraphStore.embedded(None)
    store.load_model("m", MODEL.encode())
    report = brick_report(store, "m")
    by_class = {c.class_iri.removeprefix(BRICK): c for c in report.unaligned_classes}
    assert set(by_class) == {"Chiller", "Supply_Air_Temprature_Setpoint"}
    assert by_class["Chiller"].count == 1 and by_class["Chiller"].unaligned == 1
    assert "brick:Supply_Air_Temperature_Sensor" in by_class["Supply_Air_Temprature_Setpoint"].needed  # misspelt
    assert [(r.predicate.removeprefix(BRICK), r.count) for r in report.unread_relations] == [("regulates", 1)]
    sat = "https://example.org/report#sat"
    assert report.points_without_unit == (sat,) and report.points_without_column == (sat,)


def test_a_saref_model_has_nothing_to_report():
    store = GraphStore.embedded(None)
    store.load_model("saref", examples_dir() / "flexlab_ahu" / "model.ttl")
    assert not brick_report(store, "saref").is_brick
