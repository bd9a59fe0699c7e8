"""The store: named-graph layout, atomic loads with clear parse errors, value binding."""

import pyoxigraph as ox
import pytest

from service.store import ONTOLOGY_GRAPH, STAGING, EmbeddedBackend, GraphStore, ModelLoadError, bind_values, insert_data_update

from case_study import CASE_STUDY, EX

BROKEN = b"""@prefix ex: <https://example.org/x#> .
ex:a ex:b ex:c .
ex:d zz:e ex:f .
"""


def _snapshot(store: GraphStore) -> set:
    return set(store.backend.store.quads_for_pattern(None, None, None, None))


def test_models_ontology_and_inferences_live_in_separate_graphs(case_store):
    graphs = {g.value.rsplit("/graph/", 1)[1] for g in case_store.backend.graphs()}
    assert {"model/case", "inferred/case", "ontology/core"} <= graphs
    case_store.load_model("other", CASE_STUDY)
    case_store.drop_model("other")
    assert case_store.models() == ["case"]
    assert case_store.backend.triple_count(case_store.model_graph("case")) > 100


def test_a_parse_error_names_file_line_and_column_and_changes_nothing(case_store, tmp_path):
    before = _snapshot(case_store)
    path = tmp_path / "broken.ttl"
    path.write_bytes(BROKEN)
    with pytest.raises(ModelLoadError) as info:
        case_store.load_model("case", path)
    assert info.value.line == 3 and info.value.column is not None
    assert str(path) in str(info.value) and "zz:" in str(info.value)
    assert _snapshot(case_store) == before


def test_unknown_format_and_empty_model_are_refused(case_store, tmp_path):
    bad = tmp_path / "model.xlsx"
    bad.write_bytes(b"x")
    with pytest.raises(ValueError, match="unsupported RDF format"):
        case_store.load_model("x", bad)
    with pytest.raises(ModelLoadError, match="empty"):
        case_store.load_model("x", b"# nothing\n", "ttl")
    with pytest.raises(ValueError, match="model name"):
        case_store.load_model("bad name", CASE_STUDY)


def test_json_ld_and_n_triples_load_the_same_triples(tmp_path):
    store = GraphStore.embedded(None)
    store.load_model("ttl", CASE_STUDY)
    for fmt, suffix in ((ox.RdfFormat.N_TRIPLES, "nt"), (ox.RdfFormat.JSON_LD, "jsonld"), (ox.RdfFormat.RDF_XML, "rdf")):
        data = store.backend.dump(store.model_graph("ttl"), fmt)
        path = tmp_path / f"model.{suffix}"
        path.write_bytes(data)
        store.load_model(suffix, path)
        assert store.backend.triple_count(store.model_graph(suffix)) == store.backend.triple_count(store.model_graph("ttl"))


def test_replacing_a_model_swaps_it_whole(case_store):
    case_store.load_model("case", b"<https://example.org/a> <https://example.org/b> <https://example.org/c> .", "nt")
    assert case_store.backend.triple_count(case_store.model_graph("case")) == 1


def test_several_graphs_are_replaced_together_and_staging_leaves_nothing_behind(tmp_path):
    """A first write loads the graphs directly; replacing existing ones stages and moves them in one
    update. Either way a blank node shared between graphs stays one node, a graph given no triples
    is removed, other graphs are untouched, and a staging graph a crash left is removed on reopen."""
    g1, g2, other = (ox.NamedNode(f"https://example.org/g/{n}") for n in ("one", "two", "other"))
    p = ox.NamedNode("https://example.org/p")
    backend = EmbeddedBackend(tmp_path / "store")
    backend.replace_graph(other, [ox.Triple(p, p, ox.Literal("kept"))])
    for version in ("first", "second"):
        shared = ox.BlankNode()
        text = ox.serialize([ox.Triple(shared, p, ox.Literal(version + " two"))], format=ox.RdfFormat.N_TRIPLES)
        backend.replace_graphs({g1: [ox.Triple(shared, p, ox.Literal(version + " one"))], g2: text})
        rows = backend.query(f"SELECT ?x WHERE {{ GRAPH {g1} {{ ?x ?p ?one }} GRAPH {g2} {{ ?x ?p ?two }} }}")
        assert len(rows) == 1 and backend.triple_count(g1) == backend.triple_count(g2) == 1, version
        assert {t.object.value for t in backend.query(f"CONSTRUCT {{ ?s ?p ?o }} WHERE {{ GRAPH {g1} {{ ?s ?p ?o }} }}")} == {version + " one"}
    # N-Triples in chunks of whole lines (as the alignment hands them over) are one graph's text
    chunks = [ox.serialize([ox.Triple(p, p, ox.Literal(f"chunk {i}"))], format=ox.RdfFormat.N_TRIPLES) for i in (1, 2)]
    backend.replace_graphs({g1: chunks})
    assert sorted(t.object.value for t in backend.query(f"CONSTRUCT {{ ?s ?p ?o }} WHERE {{ GRAPH {g1} {{ ?s ?p ?o }} }}")) == ["chunk 1", "chunk 2"]
    assert all(c.decode() in insert_data_update({g1: chunks}) for c in chunks)
    backend.replace_graphs({g1: [], g2: [ox.Triple(p, p, p)]})
    assert backend.graphs() == sorted([g2, other], key=lambda g: g.value) and backend.triple_count(other) == 1
    backend.store.add(ox.Quad(p, p, p, ox.NamedNode(STAGING + "crashed/0")))  # as a crash mid-write leaves it
    backend.store.flush()
    del backend
    assert EmbeddedBackend(tmp_path / "store").graphs() == sorted([g2, other], key=lambda g: g.value)


def test_on_disk_store_keeps_models_across_reopen(tmp_path):
    store = GraphStore.embedded(tmp_path / "data")
    store.load_model("case", CASE_STUDY)
    count = store.backend.triple_count(store.model_graph("case"))
    del store
    reopened = GraphStore.embedded(tmp_path / "data")
    assert reopened.models() == ["case"]
    assert reopened.backend.triple_count(reopened.model_graph("case")) == count


def test_named_query_binds_values_safely(case_store):
    rows = case_store.run_named_query("measurement-link", dataset="case", device=EX + "fan_power_meter")
    assert [r["series_id"].value for r in rows] == ["supply_fan_power"]
    hostile = 'x" } ; DROP ALL ; SELECT * WHERE { "'
    rows = case_store.run_named_query("measurement-link", dataset="case", device=hostile)
    assert all(not row for row in rows)  # bound as a literal: no device, nothing injected
    assert case_store.backend.triple_count(case_store.model_graph("case")) > 100
    text = bind_values("SELECT ?a WHERE { ?a ?b ?c }", {"c": ox.Literal('say "hi"\n')})
    assert 'VALUES (?c) { ("say \\"hi\\"\\n") }' in text


def test_sparql_syntax_error_is_a_value_error(case_store):
    with pytest.raises(ValueError, match="SPARQL syntax error"):
        case_store.query("SELEC ?x WHERE { ?x ?y ?z }")


def test_blank_nodes_become_the_same_iris_on_every_load():
    data = b"""@prefix ex: <https://example.org/b#> . @prefix saref: <https://saref.etsi.org/core/> .
ex:fan saref:hasPropertyValue [ saref:hasValue 1.5 ], [ saref:hasValue 2.5 ] ."""
    store = GraphStore.embedded(None)
    store.load_model("one", data)
    first = sorted(str(t) for t in store.graph_triples(store.model_graph("one")))
    store.load_model("one", data)
    assert sorted(str(t) for t in store.graph_triples(store.model_graph("one"))) == first
    values = {t.object.value for t in store.graph_triples(store.model_graph("one")) if t.predicate.value.endswith("hasPropertyValue")}
    assert values == {"https://w3id.org/graphtwin/resource/model/one/genid/0", "https://w3id.org/graphtwin/resource/model/one/genid/1"}


def test_an_old_on_disk_store_gets_the_current_ontologies_and_fresh_inferences(tmp_path):
    store = GraphStore.embedded(tmp_path / "data")
    store.load_model("case", CASE_STUDY)
    inferred = set(store.graph_triples(store.inferred_graph("case")))
    # what a store written by an older graphtwin holds: another ontology, no inferences
    store.write_graph(ONTOLOGY_GRAPH, [ox.Triple(ox.NamedNode(EX + "x"), ox.NamedNode(EX + "y"), ox.Literal("old"))])
    store.backend.drop_graph(store.inferred_graph("case"))
    del store
    reopened = GraphStore.embedded(tmp_path / "data")
    assert reopened.ensure_ontologies() is True
    assert reopened.ensure_ontologies() is False
    assert set(reopened.graph_triples(reopened.inferred_graph("case"))) == inferred
    assert GraphStore.embedded(None).ensure_ontologies() is True


def test_query_argument_errors_name_the_problem(case_store):
    with pytest.raises(ValueError, match="not both"):
        case_store.query("ASK { ?s ?p ?o }", model="case", default_graph=[ONTOLOGY_GRAPH])
    with pytest.raises(ValueError, match="query parameter device"):
        case_store.run_named_query("measurement-link", dataset="case", device="https://example.org/a b")
    with pytest.raises(TypeError, match="query parameter device"):
        case_store.run_named_query("measurement-link", dataset="case", device=[1])
    with pytest.raises(KeyError, match="known: .*measurement-link"):
        case_store.run_named_query("no-such-query")
    has_a_fan = "ASK { ?s a <https://saref.etsi.org/saref4bldg/Fan> }"
    assert case_store.query(has_a_fan, model="case") is True
    assert case_store.query(has_a_fan, model="nothing-loaded") is False
