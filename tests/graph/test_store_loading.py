"""Loading models: what each RDF format may hold, where its errors are, how blank nodes are named."""

import json
import re

import pyoxigraph as ox
import pytest

from service.errors import ModelLoadError
from service.graph.blank_nodes import skolemize
from service.graph.store import GraphStore

EX = "http://ex.org/"
KEEP = b"<http://ex.org/keep> <http://ex.org/p> <http://ex.org/o> ."
BOM = b"\xef\xbb\xbf"


@pytest.fixture
def store() -> GraphStore:
    """A store holding model ``m`` (one triple), which a failed load must leave as it is."""
    store = GraphStore.embedded(None)
    store.load_model("m", KEEP, "nt")
    return store


def _snapshot(store: GraphStore) -> set:
    return set(store.backend.store.quads_for_pattern(None, None, None, None))


@pytest.mark.parametrize("fmt, doc", [
    ("ttl", b"@prefix ex: <http://ex.org/> .\nex:a ex:b ex:c .\n"),
    ("nt", b"<http://ex.org/a> <http://ex.org/b> <http://ex.org/c> .\n"),
])
def test_a_utf8_byte_order_mark_is_skipped(fmt, doc):
    store = GraphStore.embedded(None)
    assert store.load_model("m", BOM + doc, fmt).triples == 1
    assert store.graph_triples(store.model_graph("m")) == [ox.Triple(*(ox.NamedNode(EX + n) for n in "abc"))]
    with pytest.raises(ModelLoadError) as info:  # positions count from the first character after it
        store.load_model("m", BOM + b"@prefix ex: <http://ex.org/> .\nex:a ex:b ex:c ex:d .\n", "ttl")
    assert (info.value.line, info.value.column) == (2, 16)


@pytest.mark.parametrize("doc, line, column", [
    (b"@prefix ex: <http://ex.org/> .\nex:a ex:b ex:c .\nex:a ex:b ex:c ex:d .\n", 3, 16),  # at line 3 between columns 16 and 20
    (b"@prefix ex: <http://ex.org/> .\nex:a ex:b ", 2, 11),  # at line 2 column 11
    (b"@prefix ex: <http://ex.org/> .\nex:a ex:b \"abc .\n\nex:a ex:b ex:c .\n", 2, 11),  # between line 2 column 11 and line 5 …
])
def test_a_syntax_error_names_its_position_once(store, doc, line, column):
    with pytest.raises(ModelLoadError) as info:
        store.load_model("m", doc, "ttl")
    assert (info.value.line, info.value.column) == (line, column)
    assert str(info.value).startswith(f"<upload>, line {line}, column {column}: ")
    assert "Parser error" not in str(info.value) and len(re.findall(r"line \d", str(info.value))) == 1


def test_a_statement_left_open_by_its_last_line_is_pointed_at(store):
    """The error is where the next subject is read as a predicate; the mistake, a ';' for a '.', is on
    the line before (a comment and a blank line between are skipped; an IRI's '#' is no comment)."""
    doc = (b"@prefix ex: <http://ex.org/> .\nex:a ex:b <http://ex.org/c#d> ;  # the fan\n\n"
           b"ex:e a ex:Sensor .\n")
    with pytest.raises(ModelLoadError) as info:
        store.load_model("m", doc, "ttl")
    assert info.value.line == 4 and str(info.value).endswith(
        "(line 2 ends with ';', so the statement goes on here: if it was complete, end it with '.')")
    with pytest.raises(ModelLoadError) as info:  # nothing left open: no hint
        store.load_model("m", b"@prefix ex: <http://ex.org/> .\nex:a ex:b ex:c ex:d .\n", "ttl")
    assert "goes on here" not in str(info.value)


_JSON_LD_CONTEXT = {"ex": EX, "feeds": {"@id": EX + "feeds", "@type": "@id"}}


@pytest.mark.parametrize("node, iri", [
    ({"@id": "coil", "@type": "ex:Coil"}, "coil"),  # relative @id, no base
    ({"@id": "http://ex.org/valve 1", "@type": "ex:Valve"}, "http://ex.org/valve 1"),  # not an IRI
    ({"@id": "ex:sensor", "feeds": "http://ex.org/bad iri"}, "http://ex.org/bad iri"),  # an IRI value
    ({"@id": "ex:sensor", "label": "a key the context does not map"}, "label"),
])
def test_json_ld_refuses_what_it_would_drop_and_names_the_iri(store, node, iri):
    doc = {"@context": _JSON_LD_CONTEXT, "@graph": [{"@id": "ex:fan", "@type": "ex:Fan", "feeds": "ex:coil"}, node]}
    before = _snapshot(store)
    with pytest.raises(ModelLoadError, match=f"invalid IRI {re.escape(repr(iri))}"):
        store.load_model("m", json.dumps(doc).encode(), "jsonld")
    assert _snapshot(store) == before
    doc["@graph"].pop()
    assert store.load_model("m", json.dumps(doc).encode(), "jsonld").triples == 2


_RDF_XML = b"""<?xml version='1.0'?>
<rdf:RDF xmlns:rdf='http://www.w3.org/1999/02/22-rdf-syntax-ns#' xmlns:ex='http://ex.org/'>
<rdf:Description rdf:about='http://ex.org/a'><ex:p rdf:resource='http://ex.org/b'/></rdf:Description>
<rdf:Description rdf:about='http://ex.org/c'><ex:p rdf:resource='http://ex.org/d'/></rdf:Description>
</rdf:RDF>
"""


@pytest.mark.parametrize("doc, line, column, message", [
    (_RDF_XML[: _RDF_XML.index(b"<rdf:Description rdf:about='http://ex.org/c'>")], 4, 1, "no element found"),  # cut short
    (_RDF_XML.replace(b"</rdf:Description>\n<rdf:Description rdf:about='http://ex.org/c'>",
                      b"</rdf:Descr>\n<rdf:Description rdf:about='http://ex.org/c'>"), 3, 86, "mismatched tag"),
])
def test_rdf_xml_that_is_not_well_formed_is_refused_with_line_and_column(store, doc, line, column, message):
    before = _snapshot(store)
    with pytest.raises(ModelLoadError, match=f"not well-formed XML: {message}") as info:
        store.load_model("m", doc, "rdf")
    assert (info.value.line, info.value.column) == (line, column)
    assert _snapshot(store) == before
    assert store.load_model("m", _RDF_XML, "rdf").triples == 2


def test_blank_nodes_added_to_an_exported_model_stay_apart_from_its_nodes():
    """An exported model names its blank nodes ``…/genid/<n>``; blank nodes added to it and loaded
    again get numbers it does not use yet."""
    store = GraphStore.embedded(None)
    store.load_model("m", b"@prefix ex: <http://ex.org/> .\nex:fan ex:nominalFlow [ ex:value 1.5 ; ex:unit ex:M3_S ] .")
    exported = ox.serialize(store.graph_triples(store.model_graph("m")), format=ox.RdfFormat.TURTLE)
    assert b"/model/m/genid/0>" in exported
    store.load_model("m", exported + b"\n@prefix ex: <http://ex.org/> .\nex:pump ex:nominalHead [ ex:value 40.0 ; ex:unit ex:KiloPA ] .\n")
    rows = store.query("SELECT ?dev ?v ?u WHERE { ?dev ?p ?node . ?node <http://ex.org/value> ?v ; <http://ex.org/unit> ?u }", model="m")
    assert sorted((r["dev"].value, float(r["v"].value), r["u"].value) for r in rows) == [
        (EX + "fan", 1.5, EX + "M3_S"), (EX + "pump", 40.0, EX + "KiloPA")]


def test_skolemize_skips_the_iris_the_triples_and_earlier_names_hold():
    prefix = "urn:x/genid/"
    p = ox.NamedNode(EX + "p")
    a, b, c = ox.BlankNode(), ox.BlankNode(), ox.BlankNode()
    named = skolemize([ox.Triple(ox.NamedNode(prefix + "0"), p, a), ox.Triple(a, p, ox.NamedNode(prefix + "2")),
                       ox.Triple(b, p, ox.NamedNode(prefix + "x"))], prefix)
    assert [t.subject.value for t in named[1:]] == [prefix + "1", prefix + "3"]
    names: dict = {}
    assert skolemize([ox.Triple(a, p, b)], prefix, names) == [ox.Triple(ox.NamedNode(prefix + "0"), p, ox.NamedNode(prefix + "1"))]
    assert skolemize([ox.Triple(c, p, a), ox.Triple(ox.NamedNode(prefix + "2"), p, c)], prefix, names)[0] == ox.Triple(
        ox.NamedNode(prefix + "3"), p, ox.NamedNode(prefix + "0"))


def test_a_comment_longer_than_the_parsers_buffer_is_a_load_error_and_changes_nothing(store):
    """A 20 MiB Turtle document that is one long comment: pyoxigraph's buffer bound raised a
    MemoryError, which the service answered with 500."""
    before = _snapshot(store)
    with pytest.raises(ModelLoadError, match=r"model m: a token or comment too long to parse \(Reached the buffer"):
        store.load_model("m", b"#" + b"x" * (20 * 1024 * 1024) + b"\n", "ttl", source_name="model m")
    assert _snapshot(store) == before
