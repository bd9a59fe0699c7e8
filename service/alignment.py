"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

Each rule is one SPARQL CONSTRUCT in ``queries/alignment/*.rq`` (its header says what it derives and
why): v3 spellings to v3.2.1/v4 ones, v1.1.2 nominal values to the v2.1.1 PropertyValue chain, QUDT
quantity kinds to property classes, measuring-device classes from what a device observes. The rules
run over the model, the ontology subsets and what they have inferred so far, in file-name order,
until a round adds nothing (a fixpoint; rules only add triples, so this terminates). The result
replaces the model's ``inferred`` graph in one transaction; the user's graph is never changed.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import pyoxigraph as ox

from .resources import queries_dir

__all__ = ["alignment_rules", "align_model", "MAX_ROUNDS"]

#: Safety cap on fixpoint rounds (the shipped rules need at most three).
MAX_ROUNDS = 8


@lru_cache(maxsize=None)
def alignment_rules(folder: str | None = None) -> tuple[tuple[str, str], ...]:
    """``(file name, query text)`` of every rule, in file-name order."""
    root = queries_dir() / "alignment" if folder is None else Path(folder)
    return tuple((p.name, p.read_text(encoding="utf-8")) for p in sorted(root.glob("*.rq")))


def align_model(store, name: str) -> int:
    """Run the alignment rules for model ``name`` and write ``inferred/<name>``; returns its size."""
    model, inferred, ontology = store.matching_dataset(name)
    derived: set[ox.Triple] = set()
    store.backend.drop_graph(inferred)
    for _ in range(MAX_ROUNDS):
        before = len(derived)
        for _name, text in alignment_rules():
            derived.update(store.backend.query(text, default_graph=[model, inferred, ontology]))
        if len(derived) == before:
            break
        store.write_graph(inferred, derived)
    return len(derived)
