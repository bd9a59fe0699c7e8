"""The SPARQL endpoint backend against a real Oxigraph server (``oxigraph_server.py``), compared with
the embedded backend wherever both should answer the same."""

from __future__ import annotations

import threading

import pyoxigraph as ox
import pytest
from case_study import CASE_STUDY, EX
from oxigraph_server import endpoint_backend, free_loopback_port, oxigraph_server  # noqa: F401 (pytest fixtures)

from service.errors import ModelLoadError, StoreRequestError, StoreUnavailableError, StoreUnreachableError
from service.graph.backend import EmbeddedBackend
from service.graph.endpoint import SparqlEndpointBackend
from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.model.summary import assembly_to_dict

X = "https://example.org/x#"
G1 = ox.NamedNode("https://example.org/graph/one")
G2 = ox.NamedNode("https://example.org/graph/two")
XSD_INTEGER = ox.NamedNode("http://www.w3.org/2001/XMLSchema#integer")
LABEL = "<http://www.w3.org/2000/01/rdf-schema#label>"

DATA = f"""@prefix ex: <{X}> .
@prefix rdfs: <http://www.w3.org/2000/01/rdf-schema#> .
ex:fan rdfs:label "Zuluftventilator"@de ; ex:tag "supply" ; ex:nominalPower 750 ; ex:part [ ex:tag "motor" ] .
ex:coil rdfs:label "Heating coil" ; ex:tag "heating" .
""".encode()
DATA_TRIPLES = 7  # 5 about the fan and its part, 2 about the coil

BROKEN = b"""@prefix ex: <https://example.org/x#> .
ex:a ex:b ex:c .
ex:d zz:e ex:f .
"""


def _contents(backend) -> dict[str, set[ox.Triple]]:
    """Every named graph of ``backend`` with its triples, read through the graph store protocol dump."""
    return {g.value: {ox.Triple(q.subject, q.predicate, q.object)
                      for q in ox.parse(backend.dump(g, ox.RdfFormat.N_TRIPLES), format=ox.RdfFormat.N_TRIPLES)}
            for g in backend.graphs()}


def _count_requests(backend: SparqlEndpointBackend) -> list[str]:
    """The URLs of the requests ``backend`` sends from now on."""
    sent: list[str] = []
    backend.client.event_hooks["request"].append(lambda request: sent.append(str(request.url)))
    return sent


def test_select_ask_and_construct_give_pyoxigraph_terms(endpoint_backend):
    assert endpoint_backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE) == DATA_TRIPLES
    rows = endpoint_backend.query(
        f"PREFIX ex: <{X}> SELECT ?label ?power ?part ?none WHERE {{ ex:fan {LABEL} ?label ; "
        f"ex:nominalPower ?power ; ex:part ?part OPTIONAL {{ ex:fan ex:missing ?none }} }}",
        default_graph=[G1],
    )
    assert len(rows) == 1 and set(rows[0]) == {"label", "power", "part"}  # the unbound ?none is absent
    assert rows[0]["label"] == ox.Literal("Zuluftventilator", language="de")
    assert rows[0]["power"] == ox.Literal("750", datatype=XSD_INTEGER)
    assert isinstance(rows[0]["part"], ox.BlankNode)
    assert endpoint_backend.query(f"ASK {{ <{X}coil> ?p ?o }}", default_graph=[G1]) is True
    assert endpoint_backend.query(f"ASK {{ <{X}coil> ?p ?o }}", default_graph=[G2]) is False
    construct = f"CONSTRUCT {{ ?s <{X}tag> ?t }} WHERE {{ ?s <{X}tag> ?t FILTER(isIRI(?s)) }}"
    embedded = EmbeddedBackend(None)
    embedded.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
    constructed = endpoint_backend.query(construct, default_graph=[G1])
    assert len(constructed) == 2 and set(constructed) == set(embedded.query(construct, default_graph=[G1]))


def test_substitutions_bind_as_in_the_embedded_store(endpoint_backend):
    embedded = EmbeddedBackend(None)
    query = (f"PREFIX ex: <{X}>\n# a comment with WHERE {{ in it\n"
             f"SELECT ?label WHERE {{ ?device ex:tag ?tag ; {LABEL} ?label }}")
    cases = [
        {"device": ox.NamedNode(X + "coil"), "tag": ox.Literal("heating")},
        {"device": ox.NamedNode(X + "coil"), "tag": ox.Literal("supply")},
        {"tag": ox.Literal("supply")},
        {"tag": ox.Literal('x" } } ; DROP ALL ; SELECT * WHERE { "')},  # a value, never SPARQL text
    ]
    for backend in (endpoint_backend, embedded):
        backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
    answers = [endpoint_backend.query(query, substitutions=case, default_graph=[G1]) for case in cases]
    assert answers == [embedded.query(query, substitutions=case, default_graph=[G1]) for case in cases]
    assert [len(a) for a in answers] == [1, 0, 1, 0]
    assert endpoint_backend.triple_count(G1) == DATA_TRIPLES


def test_graph_patterns_see_every_named_graph_as_in_the_embedded_store(endpoint_backend):
    """With a default graph, ``GRAPH ?g`` still ranges over all named graphs; 300 of them do not fit
    in a URL, so the dataset must travel in the body."""
    embedded = EmbeddedBackend(None)
    many = " ".join(f"GRAPH <https://example.org/graph/run/{i:04d}> {{ <urn:run:{i}> <urn:p> {i} }}" for i in range(300))
    for backend in (endpoint_backend, embedded):
        backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
        backend.update(f"INSERT DATA {{ {many} }}")
    query = "SELECT DISTINCT ?g WHERE { GRAPH ?g { ?s ?p ?o } }"
    remote = sorted(r["g"].value for r in endpoint_backend.query(query, default_graph=[G1]))
    assert len(remote) == 301
    assert remote == sorted(r["g"].value for r in embedded.query(query, default_graph=[G1]))


def test_replace_graph_is_one_request_and_atomic_for_a_concurrent_reader(endpoint_backend):
    size, replacements = 5000, 8
    marker = ox.NamedNode(X + "generation")

    def generation(number: int) -> list[ox.Triple]:
        return [ox.Triple(ox.NamedNode(f"{X}n{i}"), marker, ox.Literal(number)) for i in range(size)]

    sent = _count_requests(endpoint_backend)
    endpoint_backend.replace_graph(G1, generation(0))
    assert sent == [endpoint_backend.update_url]
    seen: list[dict[int, int]] = []
    done = threading.Event()

    def read() -> None:
        with SparqlEndpointBackend(endpoint_backend.query_url, endpoint_backend.update_url,
                                   endpoint_backend.store_url) as reader:
            while not done.is_set():
                rows = reader.query(f"SELECT ?gen (COUNT(*) AS ?n) WHERE {{ GRAPH {G1} {{ ?s {marker} ?gen }} }} GROUP BY ?gen")
                seen.append({int(r["gen"].value): int(r["n"].value) for r in rows})

    thread = threading.Thread(target=read)
    thread.start()
    try:
        for number in range(1, replacements + 1):
            endpoint_backend.replace_graph(G1, generation(number))
    finally:
        done.set()
        thread.join()
    assert sent == [endpoint_backend.update_url] * (1 + replacements)
    assert seen, "the reader never ran"
    partial = [counts for counts in seen if len(counts) != 1 or next(iter(counts.values())) != size]
    assert not partial, f"a reader saw an empty or half-replaced graph: {partial[:3]}"
    assert len({next(iter(counts)) for counts in seen}) > 1, "the reader saw no replacement happen"
    assert endpoint_backend.query(f"SELECT DISTINCT ?gen WHERE {{ GRAPH {G1} {{ ?s {marker} ?gen }} }}") == [
        {"gen": ox.Literal(replacements)}
    ]


def test_an_update_request_fails_as_a_whole_as_in_the_embedded_store(endpoint_backend):
    """The second operation fails at run time (not a syntax error): the first one is not applied."""
    request = f"INSERT DATA {{ GRAPH {G1} {{ <urn:a> <urn:b> <urn:c> }} }} ; DROP GRAPH {G2}"
    for backend in (endpoint_backend, EmbeddedBackend(None)):
        with pytest.raises(RuntimeError, match="does not exist") as info:
            backend.update(request)
        assert not isinstance(info.value, ValueError)
        assert backend.graphs() == []
    with pytest.raises(StoreUnavailableError, match=f"{endpoint_backend.update_url}.*HTTP 500"):
        endpoint_backend.update(request)


def test_drop_graphs_and_triple_count(endpoint_backend):
    endpoint_backend.load_graph(G1, DATA, ox.RdfFormat.TURTLE)
    endpoint_backend.load_graph(G2, b"<urn:a> <urn:b> <urn:c> .", ox.RdfFormat.N_TRIPLES)
    assert endpoint_backend.graphs() == [G1, G2]
    assert (endpoint_backend.triple_count(G1), endpoint_backend.triple_count(G2)) == (DATA_TRIPLES, 1)
    endpoint_backend.drop_graph(G1)
    endpoint_backend.drop_graph(G1)  # absent: not an error
    assert endpoint_backend.graphs() == [G2]
    assert endpoint_backend.triple_count(G1) == 0
    endpoint_backend.replace_graph(G2, [])
    assert endpoint_backend.graphs() == []


@pytest.mark.parametrize("fmt", [ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES, ox.RdfFormat.RDF_XML, ox.RdfFormat.JSON_LD])
def test_dump_round_trips(endpoint_backend, fmt):
    data = DATA.replace(b'ex:part [ ex:tag "motor" ] ', b"ex:part ex:motor ")  # no blank node: comparable sets
    endpoint_backend.load_graph(G1, data, ox.RdfFormat.TURTLE)
    original = {ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(data, format=ox.RdfFormat.TURTLE)}
    dumped = endpoint_backend.dump(G1, fmt)
    assert {ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(dumped, format=fmt)} == original
    endpoint_backend.load_graph(G2, dumped, fmt)
    assert _contents(endpoint_backend)[G2.value] == original
    endpoint_backend.drop_graph(G2)
    assert endpoint_backend.dump(G2, fmt) == b""


def test_sparql_syntax_errors_are_value_errors_with_the_servers_text(endpoint_backend):
    with pytest.raises(StoreRequestError) as info:
        endpoint_backend.query("SELEC ?x WHERE { ?x ?y ?z }")
    assert isinstance(info.value, ValueError)
    message = str(info.value)
    assert endpoint_backend.query_url in message and "HTTP 400" in message and "1:1" in message  # where, per the server
    with pytest.raises(ValueError, match="update.*HTTP 400"):
        endpoint_backend.update("INSERT DATA { <urn:a> <urn:b> }")
    with pytest.raises(ValueError, match="HTTP 400"):
        GraphStore(endpoint_backend).query("SELECT ?x WHERE { ?x", model="case")
    assert endpoint_backend.graphs() == []


def test_bad_turtle_raises_before_sending_and_leaves_the_server_unchanged(endpoint_backend):
    store = GraphStore(endpoint_backend)
    store.load_model("case", CASE_STUDY)
    before = _contents(endpoint_backend)
    sent = _count_requests(endpoint_backend)
    with pytest.raises(ModelLoadError) as info:
        endpoint_backend.load_graph(G1, BROKEN, ox.RdfFormat.TURTLE, source_name="broken.ttl")
    assert (info.value.source, info.value.line) == ("broken.ttl", 3) and info.value.column is not None
    assert "zz:" in str(info.value)
    assert sent == []
    with pytest.raises(ModelLoadError):
        store.load_model("case", BROKEN, "ttl")
    assert endpoint_backend.update_url not in sent
    assert _contents(endpoint_backend) == before
    assert len(before[store.model_graph("case").value]) > 100


def test_error_statuses_and_unreachable_endpoints_name_the_url(oxigraph_server):
    with SparqlEndpointBackend.for_oxigraph_server(f"{oxigraph_server.url}/no-such-prefix") as misplaced:
        with pytest.raises(StoreUnavailableError, match=f"{misplaced.query_url}.*HTTP 404") as info:
            misplaced.graphs()
        assert isinstance(info.value, RuntimeError) and not isinstance(info.value, ValueError)
    url = f"http://127.0.0.1:{free_loopback_port()}"
    with SparqlEndpointBackend.for_oxigraph_server(url, timeout_s=2) as dead:
        with pytest.raises(StoreUnreachableError, match=f"cannot reach SPARQL endpoint {url}/update") as info:
            dead.drop_graph(G1)
        assert isinstance(info.value, ConnectionError) and isinstance(info.value, RuntimeError)


@pytest.mark.parametrize("token", [None, "s3cret-token"])
def test_bearer_token_header_only_when_given(oxigraph_server, token):
    with SparqlEndpointBackend.for_oxigraph_server(oxigraph_server.url, token=token) as backend:
        headers = []
        backend.client.event_hooks["request"].append(lambda request: headers.append(request.headers.get("authorization")))
        assert backend.query("ASK {}") is True
        assert backend.dump(G1, ox.RdfFormat.TURTLE) == b""
    assert headers == [None if token is None else f"Bearer {token}"] * 2


def test_graph_store_on_the_endpoint_loads_aligns_assembles_and_queries_like_the_embedded_one(endpoint_backend):
    remote = GraphStore(endpoint_backend)
    embedded = GraphStore.embedded(None)
    for store in (remote, embedded):
        assert store.load_model("case", CASE_STUDY).triples > 100
    assert remote.models() == embedded.models() == ["case"]
    for graph in (remote.model_graph("case"), remote.inferred_graph("case")):
        assert set(remote.graph_triples(graph)) == set(embedded.graph_triples(graph))
    assert remote.backend.triple_count(remote.inferred_graph("case")) > 0  # alignment wrote through the backend

    remote_model, embedded_model = assemble(remote, "case"), assemble(embedded, "case")
    assert remote_model.components.keys() == embedded_model.components.keys() and remote_model.components
    assert remote_model.targets == embedded_model.targets and remote_model.targets
    assert assembly_to_dict(remote_model) == assembly_to_dict(embedded_model)

    link = remote.run_named_query("measurement-link", dataset="case", device=EX + "fan_power_meter")
    assert link == embedded.run_named_query("measurement-link", dataset="case", device=EX + "fan_power_meter")
    assert [row["series_id"].value for row in link] == ["supply_fan_power"]
    edges = remote.run_named_query("flow-edges", dataset="case")
    assert edges and sorted(map(str, edges)) == sorted(map(str, embedded.run_named_query("flow-edges", dataset="case")))

    remote.drop_model("case")
    assert remote.models() == []
