"""Signature → SPARQL and the nearest-traverse matcher, on chains, loops and parallel branches."""

import pyoxigraph as ox
import pytest

from service.components.library import SignatureLibrary, load_signature
from service.graph.store import GraphStore
from service.matching import matcher as signature_matcher
from service.matching.compiler import compile_signature
from service.matching.matcher import MatchSession, match_signature, missing_class_report
from service.matching.signature import signature_from_dict
from service.resources import signatures_dir
from tests.bench.campus_graph import CAMPUS_NAMESPACE, campus_turtle

X = "https://example.org/t#"
ONTOLOGY = f"""
@prefix x: <{X}> . @prefix rdfs: <http://www.w3.org/2000/01/rdf-schema#> .
@prefix owl: <http://www.w3.org/2002/07/owl#> .
x:Equipment a owl:Class . x:Fan rdfs:subClassOf x:Equipment . x:Coil rdfs:subClassOf x:Equipment .
x:MixingBox rdfs:subClassOf x:Equipment . x:Sensor a owl:Class . x:Room a owl:Class .
x:PropertyValue a owl:Class .
"""


def _store(turtle: str) -> ox.Store:
    store = ox.Store()
    store.load((f"@prefix x: <{X}> .\n" + ONTOLOGY + turtle).encode(), ox.RdfFormat.TURTLE)
    return store


def _sensor_upstream(optional: bool = False):
    triple = {"subject": "up", "predicate": X + "feeds", "object": "sensor", "rule": "traverse"}
    if optional:
        triple["optional"] = True
    return signature_from_dict({
        "id": "Probe", "modeled_nodes": ["sensor"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"sensor": {"classes": [X + "Sensor"]}, "up": {"classes": [X + "Equipment", X + "Sensor"]}},
        "triples": [triple],
    })


def _pairs(matches, a="up", b="sensor"):
    pairs = [(m[a].rsplit("#")[-1] if m[a] else None, m[b].rsplit("#")[-1]) for m in matches]
    return sorted(pairs, key=lambda pair: (pair[0] or "", pair[1]))


def test_traverse_finds_only_the_nearest_upstream_match():
    store = _store("x:s_a a x:Sensor ; x:feeds x:duct . x:duct x:feeds x:s_b . x:s_b a x:Sensor ; x:feeds x:fan . "
                   "x:fan a x:Fan ; x:feeds x:s_c . x:s_c a x:Sensor .")
    # s_a reaches s_c too, but only through s_b and the fan: not the nearest
    assert _pairs(match_signature(store, _sensor_upstream())) == [("fan", "s_c"), ("s_a", "s_b")]


def test_traverse_is_exact_on_a_recirculation_loop():
    # outdoor sensor → mixing box → fan → coil → supply sensor → room → return sensor → mixing box
    store = _store("""
        x:oat a x:Sensor ; x:feeds x:mix . x:mix a x:MixingBox ; x:feeds x:fan . x:fan a x:Fan ; x:feeds x:coil .
        x:coil a x:Coil ; x:feeds x:sat . x:sat a x:Sensor ; x:feeds x:room . x:room a x:Room ; x:feeds x:rat .
        x:rat a x:Sensor ; x:feeds x:mix .""")
    assert _pairs(match_signature(store, _sensor_upstream())) == [("coil", "sat"), ("sat", "rat")]


def test_a_loop_back_to_the_start_makes_no_node_its_own_partner():
    # a sensor alone on a closed loop reaches itself round the room: that is no upstream device
    store = _store("x:s_a a x:Sensor ; x:feeds x:room . x:room a x:Room ; x:feeds x:s_a .")
    assert _pairs(match_signature(store, _sensor_upstream())) == []
    # with a fan on the loop, the fan is the sensor's upstream device, not the sensor itself
    store = _store("x:s_a a x:Sensor ; x:feeds x:room . x:room a x:Room ; x:feeds x:fan . "
                   "x:fan a x:Fan ; x:feeds x:s_a .")
    assert _pairs(match_signature(store, _sensor_upstream())) == [("fan", "s_a")]


def _upstream_of_box():
    return signature_from_dict({
        "id": "Mix", "modeled_nodes": ["mix"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"mix": {"classes": [X + "MixingBox"]}, "inlet": {"classes": [X + "Sensor"]}},
        "triples": [{"subject": "inlet", "predicate": X + "feeds", "object": "mix", "rule": "traverse"}],
    })


def test_on_a_loop_through_the_mixing_box_the_nearer_of_two_sensors_wins():
    # mix → fan → sat → room → rat_far → duct → rat_near → damper → mix (and oat → mix): both return
    # sensors are upstream of the box, and so is sat, round the loop; only rat_near is nearest
    store = _store("""
        x:oat a x:Sensor ; x:feeds x:mix . x:mix a x:MixingBox ; x:feeds x:fan . x:fan a x:Fan ; x:feeds x:sat .
        x:sat a x:Sensor ; x:feeds x:room . x:room a x:Room ; x:feeds x:rat_far . x:rat_far a x:Sensor ; x:feeds x:duct .
        x:duct x:feeds x:rat_near . x:rat_near a x:Sensor ; x:feeds x:damper . x:damper x:feeds x:mix .""")
    assert _pairs(match_signature(store, _upstream_of_box()), "inlet", "mix") == [("oat", "mix"), ("rat_near", "mix")]
    # each sensor on the loop sees the equipment or sensor right before it, never the box behind the fan
    assert _pairs(match_signature(store, _sensor_upstream())) == [
        ("fan", "sat"), ("rat_far", "rat_near"), ("sat", "rat_far")]


def test_an_optional_block_with_a_traverse_binds_the_nearest_node_whole_or_not_at_all():
    signature = signature_from_dict({
        "id": "Labelled", "modeled_nodes": ["sensor"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"sensor": {"classes": [X + "Sensor"]}, "up": {"classes": [X + "Equipment"]}, "label": {"literal": True}},
        "triples": [
            {"subject": "up", "predicate": X + "feeds", "object": "sensor", "rule": "traverse", "optional": True},
            {"subject": "up", "predicate": X + "label", "object": "label", "rule": "optional"},
        ],
    })
    # s1's nearest equipment (the coil) has no label: the labelled fan further up must not be taken
    store = _store('x:fan a x:Fan ; x:label "supply fan" ; x:feeds x:coil . x:coil a x:Coil ; x:feeds x:s1 . '
                   'x:s1 a x:Sensor . x:fan2 a x:Fan ; x:label "return fan" ; x:feeds x:s2 . x:s2 a x:Sensor .')
    found = {m["sensor"].rsplit("#")[-1]: (m["up"] and m["up"].rsplit("#")[-1], m["label"]) for m in match_signature(store, signature)}
    assert found == {"s1": (None, None), "s2": ("fan2", "return fan")}


def test_campus_units_match_their_nearest_devices_round_the_return_loop():
    store = GraphStore.embedded(None)
    store.load_model("campus", campus_turtle(2, n_rooms=3).encode())
    library = SignatureLibrary.load()
    session = MatchSession(store, store.matching_dataset("campus"))
    matches = {sid: match_signature(store, sig, session=session) for sid, sig in library.items()}
    assert not [sid for sid, found in matches.items() if not found]  # the bench campus exercises every signature
    unit = f"{CAMPUS_NAMESPACE}ahu0#"
    fans = {m["fan"][len(unit):]: (m["flow_source"][len(unit):], m["inlet"][len(unit):])
            for m in matches["Fan"] if m["fan"].startswith(unit)}
    assert fans == {"supply_fan": ("supply_flow_meter", "cooling_coil"),
                    "return_fan": ("return_flow_meter", "return_air_sensor")}
    boxes = {(m["outdoor_sensor"][len(unit):], m["return_sensor"][len(unit):]) for m in matches["MixingBox"]
             if m["box"].startswith(unit)}
    assert boxes == {("outdoor_air_sensor", "return_air_sensor")}
    # the supply flow meter sits after the mixing box: the return fan behind it is not its source
    meters = {m["meter"][len(unit):]: m["upstream"] for m in matches["FlowMeter"] if m["meter"].startswith(unit)}
    assert meters == {"supply_flow_meter": None, "return_flow_meter": None}
    # the coils draw their air through to the supply fan, not from the return fan behind the mixing box
    assert {m["fan"][len(unit):] for sid in ("CoolingCoil", "HeatingCoil", "HotWaterLoop", "ConstantHeatGain")
            for m in matches[sid] if m["fan"].startswith(unit)} == {"supply_fan"}
    # a shared session gives what a fresh one does
    assert match_signature(store, library["HotWaterLoop"], default_graph=store.matching_dataset("campus")) == \
        matches["HotWaterLoop"]


def test_parallel_branches_both_match():
    store = _store("""x:oat a x:Sensor ; x:feeds x:mix . x:rat a x:Sensor ; x:feeds x:mix .
        x:mix a x:MixingBox ; x:feeds x:mat . x:mat a x:Sensor .""")
    signature = signature_from_dict({
        "id": "Mix", "modeled_nodes": ["mix"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"mix": {"classes": [X + "MixingBox"]}, "inlet": {"classes": [X + "Sensor"]}},
        "triples": [{"subject": "inlet", "predicate": X + "feeds", "object": "mix", "rule": "traverse"}],
    })
    assert _pairs(match_signature(store, signature), "inlet", "mix") == [("oat", "mix"), ("rat", "mix")]


def test_optional_traverse_leaves_a_boundary_sensor_unbound():
    store = _store("x:oat a x:Sensor . x:fan a x:Fan ; x:feeds x:sat . x:sat a x:Sensor .")
    assert _pairs(match_signature(store, _sensor_upstream(optional=True))) == [(None, "oat"), ("fan", "sat")]


def test_an_optional_chain_binds_whole_or_not_at_all():
    signature = signature_from_dict({
        "id": "Nominal", "modeled_nodes": ["fan"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"fan": {"classes": [X + "Fan"]}, "pv": {"classes": [X + "PropertyValue"]}, "value": {"literal": True},
                  "unit": {"any": True}},
        "triples": [
            {"subject": "fan", "predicate": X + "hasValue", "object": "pv", "rule": "optional"},
            {"subject": "pv", "predicate": X + "value", "object": "value", "rule": "optional"},
            {"subject": "pv", "predicate": X + "unit", "object": "unit", "rule": "optional"},
        ],
    })
    store = _store('x:f1 a x:Fan ; x:hasValue x:pv1 . x:pv1 a x:PropertyValue ; x:value "1.5" ; x:unit x:m3s . '
                   'x:f2 a x:Fan ; x:hasValue x:pv2 . x:pv2 a x:PropertyValue ; x:value "2.0" . '
                   'x:f3 a x:Fan .')
    found = {m["fan"].rsplit("#")[-1]: (m["value"], m["unit"]) for m in match_signature(store, signature)}
    assert found == {"f1": ("1.5", X + "m3s"), "f2": (None, None), "f3": (None, None)}


def test_literals_come_back_intact():
    signature = signature_from_dict({
        "id": "Label", "modeled_nodes": ["fan"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"fan": {"classes": [X + "Fan"]}, "label": {"literal": True}},
        "triples": [{"subject": "fan", "predicate": X + "label", "object": "label"}],
    })
    store = _store('x:f a x:Fan ; x:label "a \\"quoted\\"\\nline"@en .')
    [match] = match_signature(store, signature)
    assert match["label"] == 'a "quoted"\nline' and match.literals["label"].language == "en"


def test_invalid_class_iri_is_refused_by_name():
    signature = signature_from_dict({
        "id": "Bad", "modeled_nodes": ["a"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"a": {"classes": ["https://example.org/has space>"]}},
    })
    with pytest.raises(ValueError, match="has space"):
        compile_signature(signature)


def test_a_class_no_ontology_declares_is_reported():
    store = _store("")
    signature = signature_from_dict({
        "id": "Typo", "modeled_nodes": ["a"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"a": {"classes": [X + "Fann"]}},
    })
    [problem] = missing_class_report(store, signature, None)
    assert "Fann" in problem and "Typo" in problem


def test_every_library_signature_compiles_and_runs(case_store):
    for path in sorted(signatures_dir().rglob("*.toml")):
        signature = load_signature(path)
        text = compile_signature(signature).text
        assert f"signature {signature.id}" in text
        for triple in signature.triples:  # Traverse stays a property path in the query explain prints
            if triple.rule.value == "traverse":
                path = "(fso:suppliesFluidTo+|^fso:suppliesFluidTo+)" if triple.or_reverse else "fso:suppliesFluidTo+"
                assert f"?{triple.subject} {path} ?{triple.object} ." in text
        match_signature(case_store, signature, default_graph=case_store.matching_dataset("case"))


@pytest.mark.parametrize("value, kind", [("no", "effect"), (False, "component")])
def test_can_appear_is_a_boolean_of_effects_only(value, kind):
    data = {"id": "Odd", "kind": kind, "modeled_nodes": ["a"], "model": "service.components.measuring_device:MeasuringDevice",
            "nodes": {"a": {"classes": [X + "Fan"]}}, "can_appear": value}
    if kind == "effect":
        data["splice"] = {"node": "a", "input": "value_in"}
    with pytest.raises(ValueError, match="can_appear"):
        signature_from_dict(data)


def test_typed_literals_and_blank_nodes_come_back_as_the_store_holds_them():
    # the matcher reads Oxigraph's TSV results, which write numbers and booleans bare
    signature = signature_from_dict({
        "id": "Value", "modeled_nodes": ["fan"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"fan": {"classes": [X + "Fan"]}, "value": {"any": True}},
        "triples": [{"subject": "fan", "predicate": X + "value", "object": "value"}],
    })
    store = _store('x:f a x:Fan ; x:value 42, -0.5, 1.5e3, true, "07"^^<http://www.w3.org/2001/XMLSchema#integer>, '
                   '"tab\\there", [ x:label "a node" ] .')
    held = {q.object for q in store.quads_for_pattern(None, ox.NamedNode(X + "value"), None)}
    found = match_signature(store, signature)
    assert {m.literals.get("value") or ox.BlankNode(m["value"][2:]) for m in found} == held
    assert sorted(m["value"] for m in found if "value" in m.literals) == sorted(
        t.value for t in held if isinstance(t, ox.Literal))
    assert {t.datatype.value.rsplit("#")[-1] for t in held if isinstance(t, ox.Literal)} == {
        "integer", "decimal", "double", "boolean", "string"}


def test_a_part_query_starts_from_its_node_with_fewest_instances():
    # Oxigraph evaluates a part's triples in the written order: from the one room, not the three sensors
    signature = signature_from_dict({
        "id": "InRoom", "modeled_nodes": ["sensor"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"sensor": {"classes": [X + "Sensor"]}, "room": {"classes": [X + "Room"]}},
        "triples": [{"subject": "sensor", "predicate": X + "in", "object": "room"}],
    })
    store = _store("x:s1 a x:Sensor ; x:in x:r . x:s2 a x:Sensor ; x:in x:r . x:s3 a x:Sensor . x:r a x:Room .")
    session = MatchSession(store)
    [part] = session.compiled(signature).parts
    assert next(line.strip() for line in part.text.splitlines() if line.strip().startswith("?")) == (
        "?room rdf:type ?room__class .")
    assert session.compiled(signature).text == compile_signature(signature).text
    assert _pairs(match_signature(store, signature, session=session), "room", "sensor") == [("r", "s1"), ("r", "s2")]


def test_each_query_reads_the_graphs_that_hold_what_it_reads_and_the_matches_span_them(monkeypatch):
    # the model holds the fans, a second graph the inferred types and links, a third the ontology
    model, inferred, ontology = (ox.NamedNode(f"{X}graph/{name}") for name in ("model", "inferred", "ontology"))
    store = ox.Store()
    store.load(ONTOLOGY.encode(), ox.RdfFormat.TURTLE, to_graph=ontology)
    store.load(f"@prefix x: <{X}> . x:f1 a x:Fan ; x:hasValue x:pv1 . x:pv1 x:value 1.5 . x:f2 a x:Fan .".encode(),
               ox.RdfFormat.TURTLE, to_graph=model)
    store.load(f"@prefix x: <{X}> . x:pv1 a x:PropertyValue . x:f3 a x:Coil ; x:feeds x:s1 . x:s1 a x:Sensor .".encode(),
               ox.RdfFormat.TURTLE, to_graph=inferred)
    session = MatchSession(store, [model, inferred, ontology])
    fan, value, feeds = X + "Fan", X + "value", X + "feeds"
    rdf_type = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
    assert session.dataset_for(((value, None),)) == [model]  # no other graph holds x:value
    assert session.dataset_for(((feeds, None),)) == [model, inferred]
    assert session.dataset_for(((rdf_type, (fan,)),)) == [model]  # only the model types fans
    assert session.dataset_for(((rdf_type, (X + "PropertyValue",)),)) == [model, inferred]
    assert session.dataset_for(((rdf_type, None),)) == [model, inferred, ontology]  # owl:Class is a type too
    assert session.dataset_for(((value, None), ("http://www.w3.org/2000/01/rdf-schema#subClassOf", None))) == [
        model, ontology]
    nominal = signature_from_dict({
        "id": "Nominal", "modeled_nodes": ["fan"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"fan": {"classes": [X + "Equipment"]}, "pv": {"classes": [X + "PropertyValue"]}, "v": {"literal": True}},
        "triples": [{"subject": "fan", "predicate": X + "hasValue", "object": "pv", "rule": "optional"},
                    {"subject": "pv", "predicate": value, "object": "v", "rule": "optional"}],
    })
    [part] = session.compiled(nominal).parts  # subclasses from the ontology; the value's type from the inferred graph
    assert session.dataset_for(part.reads) == [model, inferred]
    found = {m["fan"].rsplit("#")[-1]: m["v"] for m in match_signature(store, nominal, session=session)}
    assert found == {"f1": "1.5", "f2": None, "f3": None}
    assert _pairs(match_signature(store, _sensor_upstream(), session=session)) == [("f3", "s1")]
    # a graph too large to look through is read by every query
    monkeypatch.setattr(signature_matcher, "_SCANNED_TRIPLES", 3)  # the inferred graph holds 4, the ontology more
    assert MatchSession(store, [model, inferred, ontology]).dataset_for(((value, None),)) == [model, inferred, ontology]


def test_a_node_typed_twice_gives_one_match():
    # typed with a class and its subclass, and the type stated in two graphs: the part's rows repeat
    graph_a, graph_b = ox.NamedNode(X + "graph/a"), ox.NamedNode(X + "graph/b")
    store = _store("")
    store.load(f"@prefix x: <{X}> . x:f a x:Fan, x:Equipment ; x:feeds x:s . x:s a x:Sensor .".encode(),
               ox.RdfFormat.TURTLE, to_graph=graph_a)
    store.load(f"@prefix x: <{X}> . x:f a x:Fan .".encode(), ox.RdfFormat.TURTLE, to_graph=graph_b)
    signature = signature_from_dict({
        "id": "Feeds", "modeled_nodes": ["up"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"up": {"classes": [X + "Equipment"]}, "s": {"classes": [X + "Sensor"]}},
        "triples": [{"subject": "up", "predicate": X + "feeds", "object": "s"}],
    })
    default = ox.DefaultGraph()
    assert _pairs(match_signature(store, signature, default_graph=[graph_a, graph_b, default]), "up", "s") == [("f", "s")]


def test_a_traverse_does_not_pass_through_a_building_space():
    # a fan coil recirculating room air: the sensor's nearest upstream device is the coil; the coil's
    # is nothing (across the room lies the supply sensor, whose air the room changes)
    store = _store("""
        @prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
        x:room a s4bldg:BuildingSpace ; x:feeds x:coil . x:coil a x:Coil ; x:feeds x:sat .
        x:sat a x:Sensor ; x:feeds x:room .""")
    coil_inlet = signature_from_dict({
        "id": "CoilInlet", "modeled_nodes": ["coil"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"coil": {"classes": [X + "Coil"]}, "up": {"classes": [X + "Sensor"]}},
        "triples": [{"subject": "up", "predicate": X + "feeds", "object": "coil", "rule": "traverse"}],
    })
    assert match_signature(store, coil_inlet) == []
    assert _pairs(match_signature(store, _sensor_upstream())) == [("coil", "sat")]


def test_a_traverse_does_not_pass_through_a_boiler():
    # a closed heating loop: the supply water sensor's nearest upstream device is not the coil's
    # return water sensor behind the boiler (the boiler heats the water between them)
    store = _store("""
        @prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
        x:supply a x:Sensor ; x:feeds x:pump . x:pump a x:Equipment ; x:feeds x:coil .
        x:coil a x:Coil ; x:feeds x:ret . x:ret a x:Sensor ; x:feeds x:boiler .
        x:boiler a s4bldg:Boiler ; x:feeds x:supply .""")
    assert _pairs(match_signature(store, _sensor_upstream())) == [("coil", "ret")]


def _coil_fan(optional: bool = False, stop_at: tuple[str, ...] = (X + "MixingBox",)):
    triple = {"subject": "fan", "predicate": X + "feeds", "object": "coil", "rule": "traverse", "or_reverse": True,
              "stop_at": list(stop_at)}
    if optional:
        triple["optional"] = True
    return signature_from_dict({
        "id": "CoilFan", "modeled_nodes": ["coil"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"coil": {"classes": [X + "Coil"]}, "fan": {"classes": [X + "Fan"]}},
        "triples": [triple],
    })


UNITS = """
    x:rfan_a a x:Fan ; x:feeds x:mix_a . x:mix_a a x:MixingBox ; x:feeds x:coil_a .
    x:coil_a a x:Coil ; x:feeds x:sensor_a . x:sensor_a a x:Sensor ; x:feeds x:sfan_a . x:sfan_a a x:Fan .
    x:mix_b a x:MixingBox ; x:feeds x:fan_b . x:fan_b a x:Fan ; x:feeds x:coil_b . x:coil_b a x:Coil ; x:feeds x:duct_b .
    x:duct_b x:feeds x:box_fan_1, x:box_fan_2 . x:box_fan_1 a x:Fan . x:box_fan_2 a x:Fan .
    x:mix_c a x:MixingBox ; x:feeds x:coil_c . x:coil_c a x:Coil ; x:feeds x:sensor_c . x:sensor_c a x:Sensor ."""


def test_or_reverse_takes_the_fan_upstream_and_downstream_only_where_there_is_none():
    # unit a draws through (return fan → mixing box → coil → supply fan): the supply fan, not the
    # return fan behind the mixing box; unit b blows through (fan → coil → two terminal-unit fans):
    # the fan upstream, not the terminal fans after it; unit c has no fan at all: no match
    store = _store(UNITS)
    signature = _coil_fan()
    assert _pairs(match_signature(store, signature), "fan", "coil") == [("fan_b", "coil_b"), ("sfan_a", "coil_a")]
    # optional: the fanless coil stays, unbound
    assert _pairs(match_signature(store, _coil_fan(optional=True)), "fan", "coil") == [
        (None, "coil_c"), ("fan_b", "coil_b"), ("sfan_a", "coil_a")]
    # without the stop at mixing boxes the return fan, upstream, would win in unit a
    assert ("rfan_a", "coil_a") in _pairs(match_signature(store, _coil_fan(stop_at=())), "fan", "coil")
    text = compile_signature(signature).text.replace(f"<{X}feeds>", "x:feeds")
    assert "?fan (x:feeds+|^x:feeds+) ?coil ." in text


def test_or_reverse_is_searched_from_the_modelled_end_when_the_pattern_binds_the_other_first():
    # a meter of each fan is bound first (the anchor), with its fan; the coil, reached only by the
    # traverse, is searched from its side: a search from the fans would pair the return fan with the
    # coil downstream of it, and the supply fan of unit a with nothing
    store = _store(UNITS + """
        x:m_rfan x:measures x:rfan_a . x:m_sfan x:measures x:sfan_a . x:m_fan_b x:measures x:fan_b .
        x:m_rfan a x:Sensor . x:m_sfan a x:Sensor . x:m_fan_b a x:Sensor .""")
    signature = signature_from_dict({
        "id": "MeteredFanCoil", "modeled_nodes": ["meter", "coil"], "model": "service.components.measuring_device:MeasuringDevice",
        "nodes": {"meter": {"classes": [X + "Sensor"]}, "fan": {"classes": [X + "Fan"]}, "coil": {"classes": [X + "Coil"]}},
        "triples": [{"subject": "meter", "predicate": X + "measures", "object": "fan"},
                    {"subject": "fan", "predicate": X + "feeds", "object": "coil", "rule": "traverse", "or_reverse": True,
                     "stop_at": [X + "MixingBox"]}],
    })
    assert sorted((m["meter"].rsplit("#")[-1], m["coil"].rsplit("#")[-1]) for m in match_signature(store, signature)) == [
        ("m_fan_b", "coil_b"), ("m_sfan", "coil_a")]
