"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

Each rule is one SPARQL CONSTRUCT in ``queries/alignment/*.rq`` (its header says what it derives and
why): SAREF v3.1.1 spellings to the v3.2.1/v4 ones, SAREF4BLDG v1.1.2 nominal values to the v2.1.1
PropertyValue chain, QUDT quantity kinds to property classes, measuring-device classes from what a
device observes (the accepted spellings are listed in ``ontologies/README.md``).

The rules run in a scratch in-memory store holding the model, the ontology subsets and what has been
derived so far, in file-name order, round after round until a round adds nothing (a fixpoint; rules
only add triples, so this terminates). Computing locally keeps the store's write of the model and its
inferences one transaction, and works the same whatever the backend. The user's graph is never
changed: the result goes to the model's ``inferred`` graph (:meth:`service.store.GraphStore.load_model`).
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache

import pyoxigraph as ox

from .resources import queries_dir

__all__ = ["MAX_ROUNDS", "alignment_rules", "inferred_triples"]

#: Safety cap on fixpoint rounds (the shipped rules reach the fixpoint in at most three).
MAX_ROUNDS = 8


@lru_cache(maxsize=1)
def alignment_rules() -> tuple[tuple[str, str], ...]:
    """``(file name, query text)`` of every rule in ``queries/alignment``, in file-name order."""
    return tuple((p.name, p.read_text(encoding="utf-8")) for p in sorted((queries_dir() / "alignment").glob("*.rq")))


def inferred_triples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple]) -> list[ox.Triple]:
    """What the alignment rules derive from ``model`` with the ``ontology`` class hierarchy: every
    derived triple not already stated in either, sorted (so equal inputs give equal outputs).

    :raises RuntimeError: when the rules have not reached a fixpoint after :data:`MAX_ROUNDS` rounds
        (a rule that keeps minting new terms).
    """
    scratch = ox.Store()
    scratch.extend(ox.Quad(t.subject, t.predicate, t.object) for t in model)
    scratch.extend(ox.Quad(t.subject, t.predicate, t.object) for t in ontology)
    stated = {ox.Triple(q.subject, q.predicate, q.object) for q in scratch}
    derived: set[ox.Triple] = set()
    for _ in range(MAX_ROUNDS):
        new = {t for _name, text in alignment_rules() for t in scratch.query(text)} - stated - derived
        if not new:
            return sorted(derived, key=str)
        derived |= new
        scratch.extend(ox.Quad(t.subject, t.predicate, t.object) for t in new)
    raise RuntimeError(f"alignment rules in {queries_dir() / 'alignment'} did not reach a fixpoint in {MAX_ROUNDS} rounds")
