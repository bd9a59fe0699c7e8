"""Alignment: canonical SAREF/FSO triples from v3 or v4 spellings, inferred device classes."""

import pyoxigraph as ox
import pytest
from case_study import EX

import service.graph.alignment_derivation
from service.graph.alignment import inferred_triples
from service.graph.namespaces import GT, RDF
from service.graph.rdf_io import parse_rdf
from service.graph.store import ONTOLOGY_GRAPH, GraphStore

V4 = b"""@prefix saref: <https://saref.etsi.org/core/> . @prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
@prefix ex: <https://example.org/a#> .
ex:fan a s4bldg:Fan ; saref:hasPropertyValue ex:nom . ex:nom a saref:PropertyValue ;
  saref:isValueOfProperty s4bldg:nominalAirFlowRate ; saref:hasValue "1.5" .
ex:sensor a s4bldg:Sensor ; saref:observes ex:t . ex:t a saref:Temperature .
"""
V3 = b"""@prefix saref: <https://saref.etsi.org/core/> . @prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
@prefix ex: <https://example.org/a#> .
ex:fan a s4bldg:Fan ; s4bldg:nominalAirFlowRate ex:nom . ex:nom a saref:Measurement ; saref:hasValue "1.5" .
ex:sensor a s4bldg:Sensor ; saref:measuresProperty ex:t . ex:t saref:isPropertyOf ex:room ;
  <http://qudt.org/schema/qudt/hasQuantityKind> <http://qudt.org/vocab/quantitykind/Temperature> .
"""

CANONICAL = """PREFIX saref: <https://saref.etsi.org/core/> PREFIX gt: <https://w3id.org/graphtwin/ontology#>
SELECT ?s ?p ?o WHERE {
  { ?s saref:hasPropertyValue ?o . BIND(saref:hasPropertyValue AS ?p) }
  UNION { ?s saref:isValueOfProperty ?o . BIND(saref:isValueOfProperty AS ?p) }
  UNION { ?s saref:observes ?o . BIND(saref:observes AS ?p) }
  UNION { ?s a gt:TemperatureSensor . BIND(gt:TemperatureSensor AS ?o) BIND(<urn:type> AS ?p) }
}"""


def _canonical(store: GraphStore, name: str) -> set:
    return {(r["s"].value, r["p"].value, r["o"].value) for r in store.query(CANONICAL, model=name)}


def test_case_study_devices_get_their_measuring_class(case_store):
    inferred = case_store.inferred_graph("case")
    typed = {(q.subject.value, q.object.value) for q in case_store.backend.store.quads_for_pattern(None, RDF.type, None, inferred)}
    assert (EX + "coil_outlet_air_temperature_sensor", GT.TemperatureSensor.value) in typed
    assert (EX + "supply_air_flow_meter", GT.FlowSensor.value) in typed  # an s4bldg:FlowMeter, not a saref:Sensor
    assert (EX + "fan_power_meter", GT.PowerMeter.value) in typed
    assert (EX + "valve_position_sensor", GT.PositionSensor.value) in typed
    # the controller observes the temperature it controls but is not a sensor
    assert not any(s == EX + "coil_outlet_air_temperature_controller" for s, _ in typed)


def test_v3_spellings_give_the_same_canonical_triples_as_v4():
    store = GraphStore.embedded(None)
    store.load_model("v4", V4)
    store.load_model("v3", V3)
    v4, v3 = _canonical(store, "v4"), _canonical(store, "v3")
    assert v3 == v4
    assert ("https://example.org/a#sensor", "urn:type", GT.TemperatureSensor.value) in v3


def test_the_users_graph_is_never_changed():
    store = GraphStore.embedded(None)
    store.load_model("v3", V3)
    model = store.model_graph("v3")
    assert not list(store.backend.store.quads_for_pattern(None, ox.NamedNode("https://saref.etsi.org/core/observes"), None, model))


def test_a_v3_nominal_value_in_a_blank_node_stays_attached_to_its_value():
    store = GraphStore.embedded(None)
    store.load_model("bnode", b"""@prefix saref: <https://saref.etsi.org/core/> . @prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
<https://example.org/a#fan> a s4bldg:Fan ; s4bldg:nominalAirFlowRate [ a saref:Measurement ; saref:hasValue 1.5 ] .""")
    rows = store.query("""PREFIX saref: <https://saref.etsi.org/core/> PREFIX s4bldg: <https://saref.etsi.org/saref4bldg/>
        SELECT ?v WHERE { ?fan saref:hasPropertyValue ?pv . ?pv saref:isValueOfProperty s4bldg:nominalAirFlowRate ; saref:hasValue ?v }""",
                       model="bnode")
    assert [float(r["v"].value) for r in rows] == [1.5]


def test_the_inferred_graph_holds_only_new_triples_and_is_a_fixpoint(case_store):
    model = case_store.graph_triples(case_store.model_graph("case"))
    inferred = case_store.graph_triples(case_store.inferred_graph("case"))
    ontology = case_store.graph_triples(ONTOLOGY_GRAPH)
    assert inferred and not set(inferred) & set(model)
    assert inferred_triples(model + inferred, ontology) == []


def test_a_rule_that_keeps_minting_terms_is_stopped_with_a_clear_error(case_store, monkeypatch):
    """A rule that reads what it writes and mints a new node each run never reaches a fixpoint: the
    scheduler re-runs it (its own output wakes it) until the cap, then says so."""
    minting = ("99-chain.rq", """PREFIX ex: <https://example.org/a#>
        CONSTRUCT { ?next ex:follows ?x } WHERE {
          { ?x a <https://saref.etsi.org/saref4bldg/Fan> } UNION { ?x ex:follows ?previous }
          BIND(IRI(CONCAT(STR(?x), "+")) AS ?next) }""")
    shipped = service.graph.alignment_derivation.alignment_rules()
    monkeypatch.setattr(service.graph.alignment_derivation, "alignment_rules", lambda: shipped + (minting,))
    model = case_store.graph_triples(case_store.model_graph("case"))
    with pytest.raises(RuntimeError, match=r"alignment rules in .*alignment did not reach a fixpoint in 8 runs per rule"):
        inferred_triples(model, case_store.graph_triples(ONTOLOGY_GRAPH))


def test_a_property_class_the_model_declares_under_saref_temperature_makes_its_observer_a_temperature_sensor():
    """Rule 50 reads entailed types only: the model's own ``rdfs:subClassOf`` and
    ``owl:equivalentClass`` take part in the entailment as the ontology's do (a device observing such
    a property becomes a sensor; a controller observing it does not)."""
    model = parse_rdf(b"""@prefix saref: <https://saref.etsi.org/core/> . @prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
@prefix rdfs: <http://www.w3.org/2000/01/rdf-schema#> . @prefix ex: <https://example.org/a#> .
@prefix owl: <http://www.w3.org/2002/07/owl#> .
ex:SupplyAirTemperature rdfs:subClassOf ex:AirTemperature . ex:AirTemperature rdfs:subClassOf saref:Temperature .
ex:sensor a s4bldg:Sensor ; saref:observes ex:t . ex:t a ex:SupplyAirTemperature .
ex:DryBulb owl:equivalentClass ex:AirTemperature . ex:bulb a s4bldg:Sensor ; saref:observes ex:d . ex:d a ex:DryBulb .
ex:controller a s4bldg:Controller ; saref:observes ex:t .
ex:other a s4bldg:Sensor ; saref:observes ex:u . ex:u a ex:Humidity .""", ox.RdfFormat.TURTLE, "model")
    ontology = GraphStore.embedded(None).graph_triples(ONTOLOGY_GRAPH)
    typed = {t.subject.value for t in inferred_triples(model, ontology) if t.object == GT.TemperatureSensor}
    assert typed == {"https://example.org/a#sensor", "https://example.org/a#bulb"}
