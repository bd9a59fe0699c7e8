"""Paths and IRIs of the case-study example used across the tests."""

from service.resources import examples_dir

CASE_STUDY = examples_dir() / "ventilation_case_study" / "model.ttl"
EX = "https://example.org/ventilation-case-study#"
