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
