"""What a SPARQL query can read (service.graph.sparql_reads): the over-approximation the alignment rules'
scheduler relies on — it may say "reads" too often, never too rarely."""

import threading

import pytest

from service.graph.alignment_derivation import alignment_rules
from service.graph.sparql_reads import QueryReads, query_reads

RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
EX = "http://example.org/"
PREFIX = f"PREFIX ex: <{EX}> "


def reads(where: str) -> QueryReads:
    return query_reads(PREFIX + "CONSTRUCT { ?x ex:out ?y } WHERE { " + where + " }")


def typed(*classes: str) -> dict[str, set[str]]:
    return {RDF_TYPE: {EX + c for c in classes}}


def test_a_class_named_or_restricted_by_values_or_in_is_all_a_type_pattern_reads():
    for where in ("?x a ex:A", "?x a ?c . VALUES ?c { ex:A ex:B }", "?x a ?c . FILTER(?c IN (ex:A, ex:B) && BOUND(?x))"):
        r = reads(where)
        assert r.may_read(typed("A")) and not r.may_read(typed("C")), where
        assert not r.may_read({EX + "p": {EX + "A"}}), where


@pytest.mark.parametrize("where", [
    "?x a ?c",
    "?x a ?c . VALUES ?c { ex:A UNDEF }",  # UNDEF frees the variable
    "{ ?x a ?c . VALUES ?c { ex:A } } UNION { ?y a ?c }",  # a branch's VALUES does not bind the other branch
    "?x a ?c . FILTER(?c IN (ex:A) || BOUND(?y))",  # a disjunction restricts nothing
    "?x a ?c . VALUES ?c { ex:A } { SELECT ?x WHERE { ?x a ?c } }",  # a sub-select's ?c is its own
    "?x a/ex:p ?c",  # rdf:type inside a path reads any class
])
def test_an_unrestricted_class_reads_every_class(where):
    assert reads(where).may_read(typed("C"))


def test_restrictions_reach_nested_groups_and_filters_inside_them_count():
    assert not reads("VALUES ?c { ex:A } ?x ex:p ?y . FILTER NOT EXISTS { ?y a ?c }").may_read(typed("C"))
    assert not reads("?x ex:p ?y . FILTER EXISTS { ?y a ?c . FILTER(?c IN (ex:A)) }").may_read(typed("C"))
    assert not reads("?x ex:p ?y . OPTIONAL { ?y a ?c . FILTER(?c IN (ex:A)) }").may_read(typed("C"))
    assert not reads("?x ex:p ?y . MINUS { ?y a ?c . VALUES ?c { ex:A } }").may_read(typed("C"))
    assert reads("?x ex:p ?y . OPTIONAL { ?y a ?c . FILTER(?c IN (ex:A)) }").may_read(typed("A"))


def test_string_literals_restrict_like_iris_but_numbers_do_not():
    r = reads('VALUES ?rule { "02.rq" "03.rq" } ?x ex:derivedBy ?rule')
    assert r.may_read({EX + "derivedBy": {"03.rq"}})
    assert not r.may_read({EX + "derivedBy": {"04.rq"}})
    assert reads("?x ex:value 1.0").may_read({EX + "value": {"1.00"}})  # the same number, other text
    assert reads("VALUES ?v { 1 2 } ?x ex:value ?v").may_read({EX + "value": {"01"}})


def test_predicates_in_paths_read_any_object_and_open_predicates_read_everything():
    r = reads("?x (ex:p|^ex:q)+/ex:r ?y")
    assert all(r.may_read({EX + p: {EX + "anything"}}) for p in "pqr")
    assert not r.may_read({EX + "s": {EX + "anything"}})
    for where in ("?x ?p ?y", "?x !(ex:p) ?y"):
        assert reads(where).may_read({EX + "s": {EX + "anything"}}), where
    assert not reads("?x ?p ?y").may_read({})  # nothing added, nothing to read


def test_a_predicate_variable_restricted_to_a_prefix_or_to_constants_reads_those_predicates_only():
    r = reads('?x ?p ?y . ?p a ex:Property . FILTER(STRSTARTS(STR(?p), "http://example.org/nominal/"))')
    assert not r.any_predicate
    assert r.may_read({EX + "nominal/airFlowRate": {EX + "anything"}})
    assert r.may_read({RDF_TYPE: {EX + "Property"}})
    assert not r.may_read({EX + "other": {EX + "anything"}})
    assert not r.may_read({RDF_TYPE: {EX + "Fan"}})
    constants = reads("?x ?p ?y . VALUES ?p { ex:a ex:b }")
    assert constants.may_read({EX + "a": {"1"}}) and not constants.may_read({EX + "c": {"1"}})
    # a prefix restricts no object: an object variable with one reads any object
    assert reads('?x ex:p ?y . FILTER(STRSTARTS(STR(?y), "http://example.org/A"))').may_read({EX + "p": {EX + "B"}})
    # a prefix and constants together: the constants (each of which the prefix may or may not admit)
    both = reads('?x ?p ?y . VALUES ?p { ex:a } FILTER(STRSTARTS(STR(?p), "http://example.org/"))')
    assert both.may_read({EX + "a": {"1"}}) and not both.may_read({EX + "b": {"1"}})
    assert reads('?x ?p ?y . FILTER(STRSTARTS(STR(?p), "http://example.org/") || BOUND(?x))').any_predicate


def test_queries_are_read_from_several_threads_at_once():
    """rdflib's SPARQL grammar is not thread-safe: two models aligned side by side parse their
    rules at the same time (without the lock every parse here failed)."""
    texts = [text for _name, text in alignment_rules()]
    errors, barrier = [], threading.Barrier(4)

    def read_all(thread: int) -> None:
        barrier.wait()
        for text in texts:
            try:
                query_reads(f"{text}\n# thread {thread}\n")  # a text of its own: not in the cache
            except Exception as exc:  # noqa: BLE001 - any failure is the finding
                errors.append(exc)

    threads = [threading.Thread(target=read_all, args=(k,)) for k in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert query_reads(texts[0] + "\n# thread 0\n") == query_reads(texts[0])
