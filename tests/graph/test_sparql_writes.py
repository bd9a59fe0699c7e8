"""Which named graphs a SPARQL update can change (service/graph/sparql_writes.py)."""

import pytest

from service.graph.sparql_writes import written_graphs

G = "https://example.org/g/"


@pytest.mark.parametrize("update, graphs", [
    (f"PREFIX ex: <https://example.org/> INSERT DATA {{ GRAPH <{G}1> {{ ex:a ex:b ex:c }} }}", {"1"}),
    (f"DELETE DATA {{ GRAPH <{G}2> {{ <urn:a> <urn:b> <urn:c> }} }} ; INSERT DATA {{ <urn:a> <urn:b> <urn:d> }}", {"2"}),
    (f"WITH <{G}3> DELETE {{ ?s ?p ?o }} INSERT {{ ?s ?p 1 }} WHERE {{ ?s ?p ?o }}", {"3"}),
    (f"WITH <{G}3> INSERT {{ GRAPH <{G}4> {{ ?s ?p ?o }} }} WHERE {{ ?s ?p ?o }}", {"4"}),  # WITH: the template's own triples
    (f"INSERT {{ GRAPH <{G}5> {{ ?s ?p ?o }} }} USING <{G}6> WHERE {{ ?s ?p ?o }}", {"5"}),  # USING is read, not written
    (f"DELETE WHERE {{ GRAPH <{G}7> {{ ?s ?p ?o }} }}", {"7"}),
    (f"DROP GRAPH <{G}8> ; CREATE GRAPH <{G}9> ; CLEAR DEFAULT", {"8"}),
    (f"MOVE <{G}10> TO <{G}11> ; COPY DEFAULT TO <{G}12> ; ADD <{G}13> TO DEFAULT", {"10", "11", "12"}),
    (f"LOAD <urn:x> INTO GRAPH <{G}14> ; LOAD <urn:y>", {"14"}),
    ("INSERT { ?s ?p ?o } WHERE { ?s ?p ?o }", set()),
    ("# a comment alone", set()),  # an empty update (valid SPARQL) changes nothing
    ("PREFIX ex: <https://example.org/>", set()),
])
def test_the_graphs_an_update_names(update, graphs):
    assert written_graphs(update) == {G + g for g in graphs}


@pytest.mark.parametrize("update", [
    "DELETE { GRAPH ?g { ?s ?p ?o } } WHERE { GRAPH ?g { ?s ?p ?o } }",
    "CLEAR ALL",
    "DROP NAMED",
    "INSERT DATA { <urn:a> ",  # rdflib cannot parse it: Oxigraph decides, and any graph may change
])
def test_an_update_that_can_change_any_named_graph(update):
    assert written_graphs(update) is None
