"""Fuzz: schemathesis generates requests from the service's OpenAPI document, for every operation
(with the write token, so the write paths are reached too) against a service holding the case study;
no request may make the service answer 5xx or break its documented response schemas."""

import pytest
from case_study import CASE_STUDY

schemathesis = pytest.importorskip("schemathesis", reason="the fuzz test needs schemathesis (the test extra has it)")
from hypothesis import HealthCheck, given, settings  # noqa: E402 (schemathesis brings hypothesis)
from hypothesis.configuration import set_hypothesis_home_dir  # noqa: E402
from schemathesis.checks import not_a_server_error  # noqa: E402
from schemathesis.specs.openapi.checks import response_schema_conformance  # noqa: E402

from service.graph.store import GraphStore  # noqa: E402
from service.http.app import create_app  # noqa: E402
from service.settings import Settings  # noqa: E402

TOKEN = "fuzz-token-0123456789"
EXAMPLES_PER_OPERATION = 25


@pytest.fixture
def app(tmp_path):
    """The service on an in-memory store holding ``case``; Hypothesis keeps its files in ``tmp_path``."""
    set_hypothesis_home_dir(tmp_path / "hypothesis")
    store = GraphStore.embedded(None)
    store.load_model("case", CASE_STUDY)
    app = create_app(Settings(data_dir=tmp_path / "service", token=TOKEN, executor="threads", query_timeout_s=5,
                              max_result_rows=200, max_upload_bytes=200_000), store=store)
    yield app
    app.state.graphtwin.runner.shutdown(wait=True)
    app.state.graphtwin.reads.close()
    set_hypothesis_home_dir(None)


def test_no_generated_request_gets_a_server_error(app):
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    operations = [result.ok() for result in schema.get_all_operations()]
    labels = {op.label for op in operations}
    assert {"PUT /models/{name}", "POST /models/{name}/measurements", "GET /sparql", "POST /sparql", "POST /sparql/update",
            "GET /queries/{name}", "POST /jobs/calibrate", "POST /jobs/{job_id}/cancel"} <= labels, labels
    for operation in operations:

        @given(case=operation.as_strategy())
        @settings(max_examples=EXAMPLES_PER_OPERATION, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        def no_server_error(case):
            response = case.call(headers={"Authorization": f"Bearer {TOKEN}"})
            case.validate_response(response, checks=[not_a_server_error, response_schema_conformance])

        no_server_error()
