"""The store: named-graph layout, atomic loads with clear parse errors, value binding."""

import re
import threading

import pyoxigraph as ox
import pytest
from case_study import CASE_STUDY, EX
from store_holder import held_by_another_process

from service.errors import ModelLoadError, NotFoundError, StoreInUseError
from service.graph.backend import STAGING, EmbeddedBackend, bind_values, insert_data_update
from service.graph.store import ALIGNMENT_RULES_GRAPH, ONTOLOGY_GRAPH, GraphStore

SAREF = "https://saref.etsi.org/core/"
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
    assert len(re.findall(r"line \d", str(info.value))) == 1  # the position once, not pyoxigraph's again
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
    for name in ("case\n", "case\r\n", "\ncase"):
        with pytest.raises(ValueError, match="model name"):
            GraphStore.check_name(name)
    assert GraphStore.check_name("case+v1.2_x-y") == "case+v1.2_x-y"


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


def test_replacing_a_model_removes_its_assembly_in_the_same_write(case_store):
    """The assembly described the model replaced: it goes with it, in the write of the new model."""
    component, p = ox.NamedNode(EX + "c"), ox.NamedNode(EX + "p")
    case_store.write_graph(case_store.assembly_graph("case"), [ox.Triple(component, p, ox.Literal("old"))])
    other = case_store.assembly_graph("other")
    case_store.write_graph(other, [ox.Triple(component, p, ox.Literal("kept"))])
    updates = []
    update = case_store.backend.update
    case_store.backend.update = lambda sparql: (updates.append(sparql), update(sparql))
    case_store.load_model("case", b"<https://example.org/a> <https://example.org/b> <https://example.org/c> .", "nt")
    assert case_store.assembly_graph("case") not in case_store.backend.graphs()
    assert len(updates) == 1 and f"DROP SILENT GRAPH {case_store.assembly_graph('case')}" in updates[0]
    assert case_store.backend.triple_count(other) == 1


def test_a_load_undone_puts_the_model_back_as_it_was(case_store):
    """A command that loads a changed model file and then fails (its measurements, an assembly that
    matches nothing) puts the stored model back: its triples, inferences and assembly; a model that
    was not there is removed again; a load that changed nothing is left."""
    assembly = [ox.Triple(ox.NamedNode(EX + "c"), ox.NamedNode(EX + "p"), ox.Literal("assembled"))]
    case_store.write_graph(case_store.assembly_graph("case"), assembly)
    graphs = (case_store.model_graph("case"), case_store.inferred_graph("case"), case_store.assembly_graph("case"))
    before = {g: set(case_store.graph_triples(g)) for g in graphs}
    other = b"<https://example.org/a> <https://example.org/b> <https://example.org/c> ."
    load = case_store.load_model("case", other, "nt", keep_previous=True)
    assert load.changed and set(case_store.graph_triples(graphs[0])) != before[graphs[0]]
    case_store.undo_load("case", load)
    assert {g: set(case_store.graph_triples(g)) for g in graphs} == before
    new = case_store.load_model("new", other, "nt", keep_previous=True)
    assert not new.replaced and case_store.has_model("new")
    case_store.undo_load("new", new)
    assert not case_store.has_model("new")
    same = case_store.load_model("case", case_store.backend.dump(graphs[0], ox.RdfFormat.N_TRIPLES), "nt",
                                 keep_previous=True)
    case_store.undo_load("case", same)
    assert not same.changed and {g: set(case_store.graph_triples(g)) for g in graphs} == before
    unkept = case_store.load_model("case", other, "nt")  # without keep_previous: nothing to put back
    with pytest.raises(ValueError, match="without keeping its graphs"):
        case_store.undo_load("case", unkept)
    assert case_store.has_model("case")


def test_a_model_loaded_again_unchanged_is_left_as_it_is(case_store):
    """Every CLI command loads its model file: one the store holds triple for triple is not written
    again, and keeps its inferences and its assembly; a changed one replaces them."""
    assembly = [ox.Triple(ox.NamedNode(EX + "c"), ox.NamedNode(EX + "p"), ox.Literal("assembled"))]
    case_store.write_graph(case_store.assembly_graph("case"), assembly)
    inferred = set(case_store.graph_triples(case_store.inferred_graph("case")))
    writes = []
    replace_graphs = case_store.backend.replace_graphs
    case_store.backend.replace_graphs = lambda graphs: (writes.append(list(graphs)), replace_graphs(graphs))
    reordered = b"\n".join(reversed(case_store.backend.dump(case_store.model_graph("case"), ox.RdfFormat.N_TRIPLES).splitlines()))
    held = case_store.backend.triple_count(case_store.model_graph("case"))
    assert case_store.load_model("case", reordered, "nt") == (held, False, True, None)
    assert writes == []
    assert case_store.graph_triples(case_store.assembly_graph("case")) == assembly
    assert set(case_store.graph_triples(case_store.inferred_graph("case"))) == inferred
    edited = reordered + b"\n<https://example.org/a> <https://example.org/b> <https://example.org/c> ."
    assert case_store.load_model("case", edited, "nt") == (held + 1, True, True, None)
    assert writes == [[case_store.model_graph("case"), case_store.inferred_graph("case"), case_store.assembly_graph("case")]]
    assert case_store.assembly_graph("case") not in case_store.backend.graphs()


def test_a_model_changed_in_the_store_is_loaded_again_from_its_file(case_store):
    # a SPARQL update removed a triple: the file is no longer what the store holds
    graph = case_store.model_graph("case")
    held = set(case_store.graph_triples(graph))
    case_store.backend.update(f"DELETE {{ GRAPH {graph} {{ ?s ?p ?o }} }} WHERE {{ GRAPH {graph} {{ ?s ?p ?o }} "
                              f"FILTER(?p = <https://saref.etsi.org/core/hasValue>) }}")
    assert set(case_store.graph_triples(graph)) < held
    case_store.load_model("case", CASE_STUDY)
    assert set(case_store.graph_triples(graph)) == held


def test_a_store_derived_with_other_alignment_rules_gets_its_inferences_again(tmp_path):
    store = GraphStore.embedded(tmp_path / "data")
    store.load_model("case", CASE_STUDY)
    inferred = set(store.graph_triples(store.inferred_graph("case")))
    rules = set(store.graph_triples(ALIGNMENT_RULES_GRAPH))
    assert {t.object.value for t in rules if t.predicate.value.endswith("label")} >= {"20-property-of.rq", "40-quantity-kinds.rq"}
    # what an older graphtwin left: one rule fewer, and its inferences without what that rule derives
    store.backend.update(f"DELETE WHERE {{ GRAPH {ALIGNMENT_RULES_GRAPH} {{ ?rule <http://www.w3.org/2000/01/rdf-schema#label> "
                         f"\"20-property-of.rq\" ; ?p ?o }} }}")
    older = [t for t in inferred if t.predicate.value not in (SAREF + "isPropertyOf", SAREF + "hasProperty")]
    assert len(older) < len(inferred)
    store.write_graph(store.inferred_graph("case"), older)
    del store
    reopened = GraphStore.embedded(tmp_path / "data")
    assert reopened.ensure_ontologies() is True
    assert set(reopened.graph_triples(ALIGNMENT_RULES_GRAPH)) == rules
    assert set(reopened.graph_triples(reopened.inferred_graph("case"))) == inferred
    reopened.load_model("case", CASE_STUDY)  # the file unchanged: the inferences stay the fresh ones
    assert set(reopened.graph_triples(reopened.inferred_graph("case"))) == inferred


class _LookingTogether:
    """A pyoxigraph store whose ``contains_named_graph`` waits (up to a second) for a second caller, so
    two writers both look which graphs exist before either writes, unless something serialises them."""

    def __init__(self, store: ox.Store):
        self._store, self._barrier = store, threading.Barrier(2)

    def __getattr__(self, name):
        return getattr(self._store, name)

    def contains_named_graph(self, graph):
        try:
            self._barrier.wait(timeout=1)
        except threading.BrokenBarrierError:  # the other writer waits for this one to finish
            pass
        return self._store.contains_named_graph(graph)


def test_two_loads_of_a_new_model_at_once_leave_one_of_them_whole():
    """Each writer finding the model missing and adding its triples would merge the two."""
    store = GraphStore.embedded(None)
    store.ensure_ontologies()
    store.backend.store = _LookingTogether(store.backend.store)
    docs = {tag: b"".join(b'<https://example.org/%s/s%d> <https://example.org/p> "%d" .\n' % (tag, i, i) for i in range(50))
            for tag in (b"A", b"B")}
    loaded = []

    def load(doc):
        loaded.append(store.load_model("x", doc, "nt"))

    writers = [threading.Thread(target=load, args=(doc,)) for doc in docs.values()]
    for writer in writers:
        writer.start()
    for writer in writers:
        writer.join()
    subjects = {t.subject.value.split("/")[3] for t in store.graph_triples(store.model_graph("x"))}
    # one created it, the other replaced it (both said "created" before: each looked before the other wrote)
    assert sorted(load[:3] for load in loaded) == [(50, True, False), (50, True, True)] and len(subjects) == 1 and store.backend.triple_count(store.model_graph("x")) == 50


def test_a_store_another_process_holds_is_refused_with_a_clear_error(tmp_path):
    path = tmp_path / "data"
    with held_by_another_process(path):
        with pytest.raises(StoreInUseError, match=r"in use by another process \(another graphtwin command, or a running graphtwin serve") as info:
            GraphStore.embedded(path)
        assert isinstance(info.value, OSError) and str(path) in str(info.value)
    held_here = EmbeddedBackend(path)
    with pytest.raises(StoreInUseError, match="open already in this process"):
        EmbeddedBackend(path)
    del held_here
    assert GraphStore.embedded(path).models() == []


@pytest.mark.parametrize("on_disk", [True, False])
def test_several_graphs_are_replaced_together_and_staging_leaves_nothing_behind(tmp_path, on_disk):
    """A first write loads the graphs directly; replacing existing ones stages and moves them in one
    update (in memory) or is one ``INSERT DATA`` update (on disk). Either way a blank node shared
    between graphs stays one node, a graph given no triples is removed, other graphs are untouched,
    no staging graph is left, and one a crash left is removed on reopen."""
    g1, g2, other = (ox.NamedNode(f"https://example.org/g/{n}") for n in ("one", "two", "other"))
    p = ox.NamedNode("https://example.org/p")
    backend = EmbeddedBackend(tmp_path / "store" if on_disk else None)
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
    if not on_disk:
        return
    backend.store.add(ox.Quad(p, p, p, ox.NamedNode(STAGING + "crashed/0")))  # as a crash mid-write leaves it
    backend.store.flush()
    del backend
    assert EmbeddedBackend(tmp_path / "store").graphs() == sorted([g2, other], key=lambda g: g.value)


@pytest.mark.parametrize("on_disk", [True, False])
def test_a_small_change_is_written_as_the_difference(tmp_path, on_disk):
    """A model edited and loaded again: one update deletes the lines it lost and inserts the new ones;
    a difference holding a blank node (which ``DELETE DATA`` cannot name) rewrites the graphs."""
    backend = EmbeddedBackend(tmp_path / "store" if on_disk else None)
    graph, other = ox.NamedNode("https://example.org/g/model"), ox.NamedNode("https://example.org/g/assembly")
    p = ox.NamedNode("https://example.org/p")
    triples = [ox.Triple(ox.NamedNode(f"https://example.org/s{i}"), p, ox.Literal(i)) for i in range(20)]
    backend.replace_graphs({graph: triples, other: [ox.Triple(p, p, p)]})
    updates = []
    update = backend.update
    backend.update = lambda sparql: (updates.append(sparql), update(sparql))

    def held():
        return set(backend.query(f"CONSTRUCT {{ ?s ?p ?o }} WHERE {{ GRAPH {graph} {{ ?s ?p ?o }} }}"))

    edited = triples[1:] + [ox.Triple(ox.NamedNode("https://example.org/new"), p, ox.Literal("new"))]
    backend.replace_graphs({graph: edited, other: []})
    assert held() == set(edited) and other not in backend.graphs()
    [sparql] = updates
    assert "DELETE DATA" in sparql and "INSERT DATA" in sparql and sparql.count("https://example.org/s") == 1
    backend.replace_graphs({graph: edited})
    assert len(updates) == 1  # nothing changed, nothing written
    with_blank = edited[:-1] + [ox.Triple(ox.BlankNode(), p, ox.Literal("blank"))]
    backend.replace_graphs({graph: with_blank})
    assert "DELETE DATA" not in updates[-1]
    assert {t.object.value for t in held()} == {t.object.value for t in with_blank}
    assert backend.graphs() == [graph]


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
    with pytest.raises(NotFoundError, match="known: .*measurement-link"):
        case_store.run_named_query("no-such-query")
    has_a_fan = "ASK { ?s a <https://saref.etsi.org/saref4bldg/Fan> }"
    assert case_store.query(has_a_fan, model="case") is True
    assert case_store.query(has_a_fan, model="nothing-loaded") is False


def test_a_load_waits_for_an_update_deriving_the_same_models_inferences(monkeypatch):
    """An update to a model graph derives the model's inferences again; a load of another model under
    that name landing in between would be followed by the update's inferences of the old model (a
    Brick model left with the case study's inferred graph, and an unchanged upload never mends it)."""
    import service.graph.store as store_module
    from service.graph.alignment import inferred_triples

    store = GraphStore.embedded(None)
    store.load_model("x", CASE_STUDY)
    deriving, go_on = threading.Event(), threading.Event()

    def slow_derivation(triples, ontology):
        deriving.set()
        go_on.wait(5)
        return inferred_triples(triples, ontology)

    monkeypatch.setattr(store_module, "inferred_triples", slow_derivation)
    insert = f'INSERT DATA {{ GRAPH {store.model_graph("x")} {{ <{EX}a> <{EX}b> "c" }} }}'
    updating = threading.Thread(target=store.update_models, args=(insert, None))
    updating.start()
    assert deriving.wait(5)
    other = b'<https://example.org/other> <http://www.w3.org/1999/02/22-rdf-syntax-ns#type> <https://saref.etsi.org/core/Sensor> .\n'
    loading = threading.Thread(target=store.load_model, args=("x", other, "nt"))
    loading.start()
    loading.join(0.5)
    assert loading.is_alive()  # waiting for the update's derivation
    go_on.set()
    updating.join(5)
    loading.join(5)
    model = store.graph_triples(store.model_graph("x"))
    assert {t.subject.value for t in model} == {"https://example.org/other"}
    assert set(store.graph_triples(store.inferred_graph("x"))) == set(inferred_triples(model, store._ontology_triples))


def test_an_unchanged_model_whose_inferred_graph_an_update_emptied_gets_it_again(case_store):
    inferred = set(case_store.graph_triples(case_store.inferred_graph("case")))
    case_store.update_models(f"CLEAR GRAPH {case_store.inferred_graph('case')}", {case_store.inferred_graph("case").value})
    assert case_store.graph_triples(case_store.inferred_graph("case")) == []
    model = case_store.backend.dump(case_store.model_graph("case"), ox.RdfFormat.N_TRIPLES)
    assert case_store.load_model("case", model, "nt").changed
    assert set(case_store.graph_triples(case_store.inferred_graph("case"))) == inferred
