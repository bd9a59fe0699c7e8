"""Paths and IRIs of the case-study example used across the tests, and its synthetic data."""

from pathlib import Path

import pyoxigraph as ox

from service.components.library import SignatureLibrary
from service.data.synthetic import SyntheticTruth, generate_synthetic_data
from service.graph.store import GraphStore
from service.matching.signature import Signature
from service.model.effect_recording import applied_effect_triples
from service.resources import examples_dir

CASE_STUDY = examples_dir() / "ventilation_case_study" / "model.ttl"
EX = "https://example.org/ventilation-case-study#"


def case_study_with_effect(effect: Signature, node: str) -> bytes:
    """The case-study model (Turtle) with ``effect`` recorded at building node ``node``, as
    ``graphtwin add-effect`` writes it."""
    recorded = ox.serialize(applied_effect_triples(effect, node), format=ox.RdfFormat.N_TRIPLES)
    return CASE_STUDY.read_bytes() + b"\n" + recorded


def case_study_data(path: Path, **generate) -> tuple[GraphStore, SyntheticTruth]:
    """An in-memory store with the case study loaded as ``case``, and synthetic data of it written to
    ``path`` (``generate``: :func:`generate_synthetic_data`'s keywords: seed, n_days, hidden_effect …)."""
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    generate.setdefault("library", SignatureLibrary.load())
    return store, generate_synthetic_data(store, "case", path, **generate)
