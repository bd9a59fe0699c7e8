"""Shared fixtures: an in-memory store with the case-study model loaded; the HTTP service's fixtures
(``service_fixtures.py``) for the tests of every floor that reaches the service."""

import os

import pytest

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# A width in the environment when the CLI is imported (exported by a shell, or set by pytest-xdist in
# its workers) is frozen into the CLI's console; tests that check wide tables set COLUMNS per invocation.
os.environ.pop("COLUMNS", None)

from case_study import CASE_STUDY  # noqa: E402

pytest_plugins = ["service_fixtures"]

from service.graph.store import GraphStore  # noqa: E402


@pytest.fixture
def case_store() -> GraphStore:
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    return store
