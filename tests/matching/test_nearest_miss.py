"""Why a pattern matches nowhere: the first required triple the graph lacks, named with its ends."""

import pyoxigraph as ox

from service.components.library import SignatureLibrary
from service.diagnosis.candidates import effect_candidates
from service.graph.store import GraphStore
from service.matching.matcher import match_signature
from service.matching.nearest_miss import nearest_miss
from service.matching.signature import signature_from_dict
from service.resources import examples_dir

X = "https://example.org/t#"
CASING_EXCHANGE = signature_from_dict({
    "id": "CasingExchange", "modeled_nodes": ["component"],
    "model": "service.components.measuring_device:MeasuringDevice",
    "nodes": {"component": {"classes": [X + "Coil"]}, "space": {"classes": [X + "Room"]},
              "air": {"classes": [X + "Temperature"]}, "sensor": {"classes": [X + "Sensor"]},
              "fan": {"classes": [X + "Fan"]}},
    "triples": [{"subject": "space", "predicate": X + "contains", "object": "component"},
                {"subject": "space", "predicate": X + "hasProperty", "object": "air"},
                {"subject": "sensor", "predicate": X + "observes", "object": "air"},
                {"subject": "fan", "predicate": X + "feeds", "object": "component", "rule": "traverse"}],
})
PLANT = "x:fan a x:Fan ; x:feeds x:duct . x:duct x:feeds x:coil . x:coil a x:Coil . "


def _store(turtle: str) -> ox.Store:
    store = ox.Store()
    store.load((f"@prefix x: <{X}> .\n" + turtle).encode(), ox.RdfFormat.TURTLE)
    return store


def test_a_graph_without_the_modeled_class_is_told_so():
    why = nearest_miss(_store("x:fan a x:Fan ."), CASING_EXCHANGE)
    assert why == f"nothing in the graph is a <{X}Coil> (its component)"


def test_the_first_missing_triple_is_named_with_the_nodes_matched_so_far_and_what_hangs_on_it():
    why = nearest_miss(_store(PLANT), CASING_EXCHANGE)
    assert why.startswith(f"the graph has no <{X}Room> at all (its ?space): no `?space <{X}contains> ?component` "
                          f"with ?space a <{X}Room> and ?component coil")
    assert f"(add `<space> <{X}contains> coil`)" in why
    assert why.endswith(f"then the triples that hang on it: `?space <{X}hasProperty> ?air`, "
                        f"`?sensor <{X}observes> ?air` (?air a <{X}Temperature>, ?sensor a <{X}Sensor>)")
    assert "feeds" not in why  # the fan is there, upstream through the duct


def test_a_later_missing_triple_is_named_alone_once_the_earlier_ones_hold():
    why = nearest_miss(_store(PLANT + "x:room a x:Room ; x:contains x:coil ; x:hasProperty x:room_air . "
                                      "x:room_air a x:Temperature ."), CASING_EXCHANGE)
    assert why == (f"the graph has no <{X}Sensor> at all (its ?sensor): no `?sensor <{X}observes> ?air` with "
                   f"?sensor a <{X}Sensor> and ?air room_air (add `<sensor> <{X}observes> room_air`)")


def test_a_pattern_that_matches_has_no_miss():
    store = _store(PLANT + "x:room a x:Room ; x:contains x:coil ; x:hasProperty x:room_air . "
                           "x:room_air a x:Temperature . x:probe a x:Sensor ; x:observes x:room_air .")
    assert match_signature(store, CASING_EXCHANGE) and nearest_miss(store, CASING_EXCHANGE) == ""


def test_the_diagnosis_says_which_triple_would_let_a_catalog_effect_apply():
    store = GraphStore.embedded(None)
    store.load_model("case", examples_dir() / "ventilation_case_study" / "model.ttl")
    _, reasons = effect_candidates(store, "case", SignatureLibrary.load())
    duct = next(reason for reason in reasons if reason.startswith("DuctHeatExchange"))
    assert ("matches nowhere: the graph has no s4bldg:BuildingSpace at all (its ?space): "
            "no `?space s4bldg:contains ?component`") in duct
    # two coil nodes could be its component: the triple to add names neither for the user
    assert "?component heating_coil_air_side or heating_coil_water_side" in duct
    assert "(add `<space> s4bldg:contains <component>`)" in duct
    assert ("CoilThermalMass at heating_coil_air_side: it extends the component models WaterCoil, HeatingWaterCoil, "
            "CoolingWaterCoil, but https://example.org/ventilation-case-study#heating_coil_air_side is modelled by "
            "HotWaterLoop") in reasons
