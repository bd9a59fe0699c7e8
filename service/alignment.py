"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

Each rule is one SPARQL CONSTRUCT in ``queries/alignment/*.rq`` (its header says what it derives and
why): SAREF v3.1.1 spellings to the v3.2.1/v4 ones, SAREF4BLDG v1.1.2 nominal values to the v2.1.1
PropertyValue chain, QUDT quantity kinds to property classes, measuring-device classes from what a
device observes (the accepted spellings are listed in ``ontologies/README.md``).

The rules run in a scratch in-memory store holding the model, the ontology subsets and what has been
derived so far, in file-name order, each seeing what the rules before it derived, round after round
until every rule has run since the last triple was added (a fixpoint; rules only add triples, so
this terminates). The order makes the rules stratified: a rule may test for the absence of a triple
(``FILTER NOT EXISTS``) only when the triple is stated in the model or derived by a rule earlier in
the order, so that its answer cannot change in a later round. The Brick rules (``0N-brick-*.rq``,
run first) use this: the sensor placement rule reads the flow edges and mixing boxes of the rules
before it.

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
from itertools import cycle, islice

import pyoxigraph as ox

from .resources import queries_dir

__all__ = ["MAX_ROUNDS", "alignment_rules", "rule_terms", "inferred_triples"]

_RDF_TYPE = ox.NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
_SUBCLASS_OF = ox.NamedNode("http://www.w3.org/2000/01/rdf-schema#subClassOf")
_PREFIX = re.compile(r"PREFIX\s+([\w-]*):\s*<([^>]+)>", re.IGNORECASE)
_TERM = re.compile(r"<([^>\s]+)>|(?<![\w?$])([A-Za-z][\w-]*):([A-Za-z_][\w-]*)")
_COMMENT = re.compile(r"(^|\s)#[^\n]*")

#: Safety cap on fixpoint rounds (the shipped rules reach the fixpoint in the first round; a rule that
#: ran after the last addition is not run again to confirm it).
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


def inferred_triples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple]) -> list[ox.Triple]:
    """What the alignment rules derive from ``model`` with the ``ontology`` class hierarchy: every
    derived triple not already stated in either, sorted (so equal inputs give equal outputs).

    :raises RuntimeError: when the rules have not reached a fixpoint after :data:`MAX_ROUNDS` rounds
        (a rule that keeps minting new terms).
    """
    model, ontology = list(model), list(ontology)
    supers = _named_superclasses(ontology)
    scratch = ox.Store()
    scratch.extend(ox.Quad(t.subject, t.predicate, t.object) for t in model)
    scratch.extend(ox.Quad(t.subject, t.predicate, t.object) for t in ontology)
    derived: list[ox.Triple] = []

    def add(triples: Iterable[ox.Triple]) -> list[ox.Triple]:
        """Add to the scratch store the triples it lacks (the store's membership test is the one set
        of what is stated, derived or entailed: no Python copy of it); those added, in order."""
        fresh, quads = [], []
        for t in dict.fromkeys(triples):
            quad = ox.Quad(t.subject, t.predicate, t.object)
            if quad not in scratch:
                fresh.append(t)
                quads.append(quad)
        scratch.extend(quads)
        return fresh

    def entail(triples: Iterable[ox.Triple]) -> None:
        add(ox.Triple(t.subject, _RDF_TYPE, c) for t in triples if t.predicate == _RDF_TYPE
            for c in supers.get(t.object, ()))

    entail(model)
    texts = [text for _name, text in alignment_rules()]
    # A rule's answer is a function of the store, so a rule need not run again until some rule (itself
    # included) has added a triple since its last run: the fixpoint is reached as soon as the rules
    # run since the last addition are all of them (at best one round and the rules before the last
    # one that added, rather than a whole confirming round).
    stale = 0
    for text in islice(cycle(texts), MAX_ROUNDS * len(texts)):
        new = add(scratch.query(text))
        stale = 0 if new else stale + 1
        if stale == len(texts):
            return sorted(derived, key=str)
        derived += new
        entail(new)
    raise RuntimeError(f"alignment rules in {queries_dir() / 'alignment'} did not reach a fixpoint in {MAX_ROUNDS} rounds")
