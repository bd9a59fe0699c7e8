"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

Each rule is one SPARQL CONSTRUCT in ``queries/alignment/*.rq`` (its header says what it derives and
why): SAREF v3.1.1 spellings to the v3.2.1/v4 ones, SAREF4BLDG v1.1.2 nominal values to the v2.1.1
PropertyValue chain, QUDT quantity kinds to property classes, measuring-device classes from what a
device observes (the accepted spellings are listed in ``ontologies/README.md``).

The rules run in a scratch in-memory store holding the model, the ontology subsets and what has been
derived so far, in file-name order, each seeing what the rules before it derived. A rule runs again
only when a triple it could read was added after its last run (:func:`service.sparql_reads.query_reads`:
the predicates of its patterns with the objects they can take, so ``VALUES ?rule {"02-…"}`` on
``gt:derivedByRule`` is not woken by every rule's provenance), the earliest such rule first, until
none is left: a fixpoint (rules only add triples, so this terminates). On a 1M-triple Brick campus
the 14 rules take 22 runs, the costly point-link and sensor-placement rules one each, where a
confirming round of every rule after the last addition doubled the time. The order makes the rules
stratified: a rule may test for the absence of a triple (``FILTER NOT EXISTS``) only when the triple
is stated in the model or derived by a rule earlier in the order, so that its answer cannot change
later. The Brick rules (``0N-brick-*.rq``, run first)
use this: the sensor placement rule reads the flow edges and mixing boxes of the rules before it.

The scratch store also holds, for every ``rdf:type`` triple of the model or derived, the types it
entails by ``rdfs:subClassOf`` in the ontology — only those a rule names (:func:`rule_terms`), so a
rule writes ``?point a brick:Temperature_Sensor`` and matches every official subclass without a
property path (``a/rdfs:subClassOf*`` per node made the Brick rules minutes long at 10⁴ triples).
These entailed triples are not part of the result: the store's queries see the hierarchy in the
ontology graph. Computing locally keeps the store's write of the model and its
inferences one transaction, and works the same whatever the backend. The user's graph is never
changed: the result goes to the model's ``inferred`` graph (:meth:`service.store.GraphStore.load_model`).

Rules that scale (tests/bench/bench_brick_alignment.py; Oxigraph plans a nested group without
knowing which of its variables the outer row binds, so it may evaluate it over the whole graph once
per outer row): inside ``OPTIONAL``, ``EXISTS`` and ``NOT EXISTS`` write ``FILTER(?c IN (…))``, not
``VALUES ?c {…}``, and test a second pattern with ``FILTER EXISTS`` rather than joining it; prefer
``MINUS`` to a ``NOT EXISTS`` that shares only bound variables with the outer pattern; filter a set of
anchors in a subquery before the patterns that read from it.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Iterable
from functools import lru_cache

import pyoxigraph as ox

from .resources import queries_dir
from .sparql_reads import query_reads

__all__ = ["MAX_ROUNDS", "alignment_rules", "rule_terms", "inferred_triples"]

_RDF_TYPE = ox.NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
_SUBCLASS_OF = ox.NamedNode("http://www.w3.org/2000/01/rdf-schema#subClassOf")
_PREFIX = re.compile(r"PREFIX\s+([\w-]*):\s*<([^>]+)>", re.IGNORECASE)
_TERM = re.compile(r"<([^>\s]+)>|(?<![\w?$])([A-Za-z][\w-]*):([A-Za-z_][\w-]*)")
_COMMENT = re.compile(r"(^|\s)#[^\n]*")

#: Safety cap on the fixpoint: at most this many runs per rule on average (the shipped rules reach it
#: in one run each, and a second of the few that read what the last ones added).
MAX_ROUNDS = 8


@lru_cache(maxsize=1)
def alignment_rules() -> tuple[tuple[str, str], ...]:
    """``(file name, query text)`` of every rule in ``queries/alignment``, in file-name order."""
    return tuple((p.name, p.read_text(encoding="utf-8")) for p in sorted((queries_dir() / "alignment").glob("*.rq")))


@lru_cache(maxsize=1)
def rule_terms() -> frozenset[str]:
    """Every IRI the rules name (full or prefixed, prefixes expanded per rule; comments ignored)."""
    terms = set()
    for _name, text in alignment_rules():
        prefixes = dict(_PREFIX.findall(text))
        for full, prefix, local in _TERM.findall(_COMMENT.sub(" ", text)):
            if full:
                terms.add(full)
            elif prefix in prefixes:
                terms.add(prefixes[prefix] + local)
    return frozenset(terms)


def _named_superclasses(ontology: Iterable[ox.Triple]) -> dict[ox.NamedNode, tuple[ox.NamedNode, ...]]:
    """class → its strict superclasses (``rdfs:subClassOf`` closure) that a rule names."""
    parents: dict[ox.NamedNode, set[ox.NamedNode]] = defaultdict(set)
    for t in ontology:
        if t.predicate == _SUBCLASS_OF and isinstance(t.object, ox.NamedNode) and isinstance(t.subject, ox.NamedNode):
            parents[t.subject].add(t.object)
    named = rule_terms()
    result = {}
    for cls in list(parents):
        seen, todo = set(), list(parents[cls])
        while todo:
            node = todo.pop()
            if node not in seen and node != cls:
                seen.add(node)
                todo += parents.get(node, ())
        supers = tuple(sorted((c for c in seen if c.value in named), key=str))
        if supers:
            result[cls] = supers
    return result


def _insert(store: ox.Store, triples: list[ox.Triple]) -> None:
    """Add ``triples`` to the default graph of ``store``: as N-Triples (serialising and parsing them in
    Rust costs a fraction of building a Python quad per triple) unless blank nodes may be among them
    (a load renames blank nodes)."""
    data = ox.serialize(triples, format=ox.RdfFormat.N_TRIPLES)
    if b"_:" in data:
        store.extend(ox.Quad(t.subject, t.predicate, t.object) for t in triples)
    else:
        store.load(data, ox.RdfFormat.N_TRIPLES)


def inferred_triples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple]) -> list[ox.Triple]:
    """What the alignment rules derive from ``model`` with the ``ontology`` class hierarchy: every
    derived triple not already stated in either, in the order the rules derived them.

    :raises RuntimeError: when the rules have not reached a fixpoint in :data:`MAX_ROUNDS` runs per
        rule (a rule that keeps minting new terms).
    """
    model, ontology = list(model), list(ontology)
    supers = _named_superclasses(ontology)
    scratch = ox.Store()
    _insert(scratch, model + ontology)
    stated = set(model).union(ontology)
    derived: list[ox.Triple] = []
    seen: set[ox.Triple] = set()  # derived or entailed

    def add(triples: Iterable[ox.Triple]) -> list[ox.Triple]:
        """Add to the scratch store the triples neither stated nor seen; those added, in order. (The
        Python sets answer what asking the store would, without building a quad per triple.)"""
        fresh = []
        for t in triples:
            if t not in seen and t not in stated:
                seen.add(t)
                fresh.append(t)
        _insert(scratch, fresh)
        return fresh

    def entail(triples: Iterable[ox.Triple]) -> list[ox.Triple]:
        return add(ox.Triple(t.subject, _RDF_TYPE, c) for t in triples if t.predicate == _RDF_TYPE
                   for c in supers.get(t.object, ()))

    entail(model)
    texts = [text for _name, text in alignment_rules()]
    reads = [query_reads(text) for text in texts]
    # A rule's answer is a function of what it reads, so it need not run again until a triple it could
    # read was added (by any rule, itself included) since its last run.
    pending = [True] * len(texts)
    for _run in range(MAX_ROUNDS * len(texts)):
        if True not in pending:
            return derived
        rule = pending.index(True)
        pending[rule] = False
        new = add(scratch.query(texts[rule]))
        derived += new
        added = defaultdict(set)
        for t in new + entail(new):
            added[t.predicate.value].add(t.object.value)
        pending = [waiting or other.may_read(added) for waiting, other in zip(pending, reads, strict=True)]
    raise RuntimeError(f"alignment rules in {queries_dir() / 'alignment'} did not reach a fixpoint in {MAX_ROUNDS} runs per rule")
