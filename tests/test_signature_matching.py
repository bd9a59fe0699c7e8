"""Signature → SPARQL and the nearest-traverse matcher, on chains, loops and parallel branches."""

import pyoxigraph as ox
import pytest

from service.resources import signatures_dir
from service.signature import load_signature, signature_from_dict
from service.signature_matcher import match_signature, missing_class_report
from service.sparql_compiler import compile_signature

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
        "id": "Probe", "modeled_nodes": ["sensor"], "model": "service.measuring_device:MeasuringDevice",
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


def test_parallel_branches_both_match():
    store = _store("""x:oat a x:Sensor ; x:feeds x:mix . x:rat a x:Sensor ; x:feeds x:mix .
        x:mix a x:MixingBox ; x:feeds x:mat . x:mat a x:Sensor .""")
    signature = signature_from_dict({
        "id": "Mix", "modeled_nodes": ["mix"], "model": "service.measuring_device:MeasuringDevice",
        "nodes": {"mix": {"classes": [X + "MixingBox"]}, "inlet": {"classes": [X + "Sensor"]}},
        "triples": [{"subject": "inlet", "predicate": X + "feeds", "object": "mix", "rule": "traverse"}],
    })
    assert _pairs(match_signature(store, signature), "inlet", "mix") == [("oat", "mix"), ("rat", "mix")]


def test_optional_traverse_leaves_a_boundary_sensor_unbound():
    store = _store("x:oat a x:Sensor . x:fan a x:Fan ; x:feeds x:sat . x:sat a x:Sensor .")
    assert _pairs(match_signature(store, _sensor_upstream(optional=True))) == [(None, "oat"), ("fan", "sat")]


def test_an_optional_chain_binds_whole_or_not_at_all():
    signature = signature_from_dict({
        "id": "Nominal", "modeled_nodes": ["fan"], "model": "service.measuring_device:MeasuringDevice",
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
        "id": "Label", "modeled_nodes": ["fan"], "model": "service.measuring_device:MeasuringDevice",
        "nodes": {"fan": {"classes": [X + "Fan"]}, "label": {"literal": True}},
        "triples": [{"subject": "fan", "predicate": X + "label", "object": "label"}],
    })
    store = _store('x:f a x:Fan ; x:label "a \\"quoted\\"\\nline"@en .')
    [match] = match_signature(store, signature)
    assert match["label"] == 'a "quoted"\nline' and match.literals["label"].language == "en"


def test_invalid_class_iri_is_refused_by_name():
    signature = signature_from_dict({
        "id": "Bad", "modeled_nodes": ["a"], "model": "service.measuring_device:MeasuringDevice",
        "nodes": {"a": {"classes": ["https://example.org/has space>"]}},
    })
    with pytest.raises(ValueError, match="has space"):
        compile_signature(signature)


def test_a_class_no_ontology_declares_is_reported():
    store = _store("")
    signature = signature_from_dict({
        "id": "Typo", "modeled_nodes": ["a"], "model": "service.measuring_device:MeasuringDevice",
        "nodes": {"a": {"classes": [X + "Fann"]}},
    })
    [problem] = missing_class_report(store, signature, None)
    assert "Fann" in problem and "Typo" in problem


def test_every_library_signature_compiles_and_runs(case_store):
    for path in sorted(signatures_dir().rglob("*.toml")):
        signature = load_signature(path)
        text = compile_signature(signature).text
        assert f"signature {signature.id}" in text
        match_signature(case_store, signature, default_graph=case_store.matching_dataset("case"))
