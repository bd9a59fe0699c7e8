"""Paths and IRIs of the case-study example used across the tests."""

import pyoxigraph as ox

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
