"""The SPARQL endpoint backend against a real Oxigraph server (fixture in ``conftest.py``)."""

from __future__ import annotations

import threading

import pyoxigraph as ox
import pytest

from case_study import CASE_STUDY, EX
from service.signature import load_signature
from service.resources import signatures_dir
from service.signature_matcher import match_signature
from service.sparql_endpoint_backend import SparqlEndpointBackend, SparqlEndpointError, SparqlRequestError
from service.store import EmbeddedBackend, GraphStore, ModelLoadError

X = "https://example.org/x#"
G1 = ox.NamedNode("https://example.org/graph/one")
G2 = ox.NamedNode("https://example.org/graph/two")
XSD_INTEGER = ox.NamedNode("http://www.w3.org/2001/XMLSchema#integer")

DATA = f"""@prefix ex: <{X}> .
@prefix rdfs: <http://www.w3.org/2000/01/rdf-schema#> .
ex:fan rdfs:label "Zuluftventilator"@de ; ex:tag "supply" ; ex:nominalPower 750 ; ex:part [ ex:tag "motor" ] .
ex:coil rdfs:label "Heating coil" ; ex:tag "heating" .
""".encode()

BROKEN = b"""@prefix ex: <https://example.org/x#> .
ex:a ex:b ex:c .
ex:d zz:e ex:f .
"""


def _all_quads(backend: SparqlEndpointBackend) -> set[tuple[str, str, str, str]]:
    rows = backend.query("SELECT ?s ?p ?o ?g WHERE { GRAPH ?g { ?s ?p ?o } }")
    return {(str(r["s"]), str(r["p"]), str(r["o"]), str(r["g"])) for r in rows}


def test_select_ask_and_construct_give_pyoxigraph_terms(endpoint_backend):
    assert endpoint_backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE) == 7  # 5 about the fan and its part, 2 about the coil
    rows = endpoint_backend.query(
        f"PREFIX ex: <{X}> SELECT ?label ?power ?part WHERE {{ ex:fan <http://www.w3.org/2000/01/rdf-schema#label> ?label ; "
        f"ex:nominalPower ?power ; ex:part ?part OPTIONAL {{ ex:fan ex:missing ?none }} }}",
        default_graph=[G1],
    )
    assert len(rows) == 1 and set(rows[0]) == {"label", "power", "part"}  # unbound ?none absent
    assert rows[0]["label"] == ox.Literal("Zuluftventilator", language="de")
    assert rows[0]["power"] == ox.Literal("750", datatype=XSD_INTEGER)
    assert isinstance(rows[0]["part"], ox.BlankNode)
    assert endpoint_backend.query(f"ASK {{ <{X}coil> ?p ?o }}", default_graph=[G1]) is True
    assert endpoint_backend.query(f"ASK {{ <{X}coil> ?p ?o }}", default_graph=[G2]) is False
    constructed = endpoint_backend.query(
        f"CONSTRUCT {{ ?s <{X}tag> ?t }} WHERE {{ ?s <{X}tag> ?t FILTER(isIRI(?s)) }}", default_graph=[G1]
    )
    assert set(constructed) == {
        ox.Triple(ox.NamedNode(X + "fan"), ox.NamedNode(X + "tag"), ox.Literal("supply")),
        ox.Triple(ox.NamedNode(X + "coil"), ox.NamedNode(X + "tag"), ox.Literal("heating")),
    }


def test_substituted_iri_and_literal_bind_by_values(endpoint_backend):
    endpoint_backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
    query = f"PREFIX ex: <{X}>\n# a comment with WHERE {{ in it\nSELECT ?label WHERE {{ ?device ex:tag ?tag ; <http://www.w3.org/2000/01/rdf-schema#label> ?label }}"
    rows = endpoint_backend.query(query, substitutions={"device": ox.NamedNode(X + "coil"), "tag": ox.Literal("heating")},
                                  default_graph=[G1])
    assert rows == [{"label": ox.Literal("Heating coil")}]
    assert endpoint_backend.query(query, substitutions={"device": ox.NamedNode(X + "coil"), "tag": ox.Literal("supply")},
                                  default_graph=[G1]) == []
    hostile = ox.Literal('x" } } ; DROP ALL ; SELECT * WHERE { "')
    assert endpoint_backend.query(query, substitutions={"tag": hostile}, default_graph=[G1]) == []
    assert endpoint_backend.triple_count(G1) == 7


def test_graph_patterns_see_every_named_graph_as_in_the_embedded_store(endpoint_backend):
    embedded = EmbeddedBackend(None)
    for backend in (endpoint_backend, embedded):
        backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
        backend.load_graph(G2, b"<urn:a> <urn:b> <urn:c> .", ox.RdfFormat.N_TRIPLES)
    query = "SELECT DISTINCT ?g WHERE { GRAPH ?g { ?s ?p ?o } }"
    remote = endpoint_backend.query(query, default_graph=[G1])
    assert sorted(r["g"].value for r in remote) == sorted(r["g"].value for r in embedded.query(query, default_graph=[G1]))
    assert sorted(r["g"].value for r in remote) == [G1.value, G2.value]


def test_replace_graph_is_atomic_for_a_concurrent_reader(endpoint_backend):
    size, generations = 3000, 6
    marker = ox.NamedNode(X + "generation")

    def triples(generation: int) -> list[ox.Triple]:
        return [ox.Triple(ox.NamedNode(f"{X}n{i}"), marker, ox.Literal(generation)) for i in range(size)]

    endpoint_backend.replace_graph(G1, triples(0))
    seen: list[dict[int, int]] = []
    done = threading.Event()

    def read() -> None:
        reader = SparqlEndpointBackend(endpoint_backend.query_url)
        while not done.is_set():
            rows = reader.query(f"SELECT ?gen (COUNT(*) AS ?n) WHERE {{ GRAPH {G1} {{ ?s {marker} ?gen }} }} GROUP BY ?gen")
            seen.append({int(r["gen"].value): int(r["n"].value) for r in rows})
        reader.close()

    thread = threading.Thread(target=read)
    thread.start()
    try:
        for generation in range(1, generations + 1):
            endpoint_backend.replace_graph(G1, triples(generation))
    finally:
        done.set()
        thread.join()
    assert seen, "the reader never ran"
    broken = [counts for counts in seen if len(counts) != 1 or next(iter(counts.values())) != size]
    assert not broken, f"a reader saw a half-replaced graph: {broken[:3]}"
    assert endpoint_backend.query(f"SELECT DISTINCT ?gen WHERE {{ GRAPH {G1} {{ ?s {marker} ?gen }} }}") == [
        {"gen": ox.Literal(generations)}
    ]


def test_drop_graphs_and_triple_count(endpoint_backend):
    endpoint_backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
    endpoint_backend.load_graph(G2, b"<urn:a> <urn:b> <urn:c> .", ox.RdfFormat.N_TRIPLES)
    assert endpoint_backend.graphs() == [G1, G2]
    assert (endpoint_backend.triple_count(G1), endpoint_backend.triple_count(G2)) == (7, 1)
    endpoint_backend.drop_graph(G1)
    endpoint_backend.drop_graph(G1)  # absent: not an error
    assert endpoint_backend.graphs() == [G2]
    assert endpoint_backend.triple_count(G1) == 0
    endpoint_backend.replace_graph(G2, [])
    assert endpoint_backend.graphs() == []


@pytest.mark.parametrize("fmt", [ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES, ox.RdfFormat.RDF_XML, ox.RdfFormat.JSON_LD])
def test_dump_round_trips(endpoint_backend, fmt):
    data = DATA.replace(b"ex:part [ ex:tag \"motor\" ] ", b"ex:part ex:motor ")
    endpoint_backend.load_graph(G1, data, ox.RdfFormat.TURTLE)
    original = {ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(data, format=ox.RdfFormat.TURTLE)}
    dumped = endpoint_backend.dump(G1, fmt)
    assert {ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(dumped, format=fmt)} == original
    assert endpoint_backend.dump(G2, fmt) == b""


def test_without_graph_store_protocol_drop_and_dump_use_sparql(endpoint_backend):
    plain = SparqlEndpointBackend(endpoint_backend.query_url, endpoint_backend.update_url)
    plain.load_graph(G1, b"<urn:a> <urn:b> \"x\"@en .", ox.RdfFormat.N_TRIPLES)
    assert plain.dump(G1, ox.RdfFormat.N_TRIPLES) == b'<urn:a> <urn:b> "x"@en .\n'
    assert plain.dump(G2, ox.RdfFormat.N_TRIPLES) == b""
    plain.drop_graph(G1)
    plain.drop_graph(G2)
    assert plain.graphs() == []
    read_only = SparqlEndpointBackend(endpoint_backend.query_url)
    with pytest.raises(SparqlEndpointError, match="read-only"):
        read_only.replace_graph(G1, [ox.Triple(ox.NamedNode("urn:a"), ox.NamedNode("urn:b"), ox.NamedNode("urn:c"))])
    plain.close()
    read_only.close()


def test_bad_sparql_is_a_value_error_with_the_servers_text(endpoint_backend):
    with pytest.raises(SparqlRequestError) as info:
        endpoint_backend.query("SELEC ?x WHERE { ?x ?y ?z }")
    assert isinstance(info.value, ValueError)
    assert endpoint_backend.query_url in str(info.value) and "HTTP 400" in str(info.value)
    assert "1:1" in str(info.value) or "expected" in str(info.value)  # the server's position / message
    with pytest.raises(SparqlRequestError, match="update"):
        endpoint_backend.update("INSERT DATA { <urn:a> <urn:b> }")


def test_bad_turtle_raises_before_sending_and_leaves_the_server_unchanged(endpoint_backend):
    endpoint_backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
    before = _all_quads(endpoint_backend)
    sent = []
    endpoint_backend.client.event_hooks["request"].append(sent.append)
    with pytest.raises(ModelLoadError) as info:
        endpoint_backend.load_graph(G1, BROKEN, ox.RdfFormat.TURTLE, source_name="broken.ttl")
    assert (info.value.source, info.value.line) == ("broken.ttl", 3) and info.value.column is not None
    assert "zz:" in str(info.value)
    assert sent == []
    endpoint_backend.client.event_hooks["request"].clear()
    assert _all_quads(endpoint_backend) == before


def test_unreachable_endpoint_and_token_header(oxigraph_server):
    from conftest import _free_loopback_port

    url = f"http://127.0.0.1:{_free_loopback_port()}"
    with SparqlEndpointBackend.for_oxigraph_server(url, timeout_s=2) as dead:
        with pytest.raises(SparqlEndpointError, match=f"cannot reach SPARQL endpoint {url}/query"):
            dead.graphs()
    with SparqlEndpointBackend.for_oxigraph_server(oxigraph_server.url, token="s3cret-token") as backend:
        headers = []
        backend.client.event_hooks["request"].append(lambda request: headers.append(request.headers.get("authorization")))
        assert backend.query("ASK {}") is True
        assert headers == ["Bearer s3cret-token"]


def test_graph_store_on_the_endpoint_loads_aligns_and_matches_like_the_embedded_one(endpoint_backend):
    remote = GraphStore(endpoint_backend)
    embedded = GraphStore.embedded(None)
    for store in (remote, embedded):
        store.load_model("case", CASE_STUDY)
    assert remote.models() == ["case"]
    for graph in (remote.model_graph("case"), remote.inferred_graph("case")):
        assert endpoint_backend.triple_count(graph) == embedded.backend.triple_count(graph) > 0
    rows = remote.run_named_query("measurement-link", dataset="case", device=EX + "fan_power_meter")
    assert [r["series_id"].value for r in rows] == ["supply_fan_power"]
    fan = load_signature(signatures_dir() / "fan.toml")
    remote_matches = match_signature(remote, fan, default_graph=remote.matching_dataset("case"))
    assert remote_matches and remote_matches == match_signature(embedded, fan, default_graph=embedded.matching_dataset("case"))
    before = _all_quads(endpoint_backend)
    with pytest.raises(ModelLoadError):
        remote.load_model("case", BROKEN, "ttl")
    assert _all_quads(endpoint_backend) == before
    with pytest.raises(ValueError, match="HTTP 400"):
        remote.query("SELEC ?x WHERE { ?x ?y ?z }")
