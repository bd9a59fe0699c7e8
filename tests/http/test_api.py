"""The HTTP service end to end: uploads, SPARQL, named queries, jobs, auth and every bad-input status,
with the store unchanged after each refusal."""

import csv
import hashlib
import io
import threading
import time

import pyoxigraph as ox
import pytest
from brick_report_model import REPORT_MODEL, REPORT_NAMESPACE
from case_study import CASE_STUDY, EX
from fastapi.testclient import TestClient
from shared_data import OFFICIAL_BRICK

from service.data.model_series import series_specs
from service.errors import StoreInUseError, StoreUnavailableError
from service.graph import query_reader
from service.graph.store import GraphStore
from service.http.app import create_app
from service.jobs.records import JobRecord, JobRecords
from service.jobs.work import JobKind, JobResult
from service.model.assembly import assemble
from service.settings import Settings
from service.workflows.requests import AssembleRequest

GT = "https://w3id.org/graphtwin/ontology#"
RUNS_PER_GRAPH = f"""PREFIX gt: <{GT}>
SELECT ?g (COUNT(DISTINCT ?run) AS ?runs) (COUNT(DISTINCT ?e) AS ?estimates)
WHERE {{ GRAPH ?g {{ {{ ?run a gt:CalibrationRun }} UNION {{ ?e a gt:Estimate }} }} }} GROUP BY ?g"""
COUNT_MODEL = "SELECT (COUNT(*) AS ?n) WHERE { ?s ?p ?o }"


def _rows(response) -> list[dict]:
    assert response.status_code == 200, response.text
    return response.json()["results"]["bindings"]


def _upload_csv(client, auth, text: str, model: str = "case", **params):
    return client.post(f"/models/{model}/measurements", content=text.encode(), params=params,
                       headers={**auth, "Content-Type": "text/csv"})


def _csv_rows(path) -> list[list[str]]:
    return list(csv.reader(path.read_text().splitlines()))


def _csv_text(rows) -> str:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(rows)
    return out.getvalue()


# ---------------------------------------------------------------------- service, models, auth
def test_health_and_the_openapi_document_list_every_resource(client):
    health = client.get("/health")
    assert health.status_code == 200 and health.json()["backend"] == "embedded"
    paths = client.get("/openapi.json").json()["paths"]
    for path in ("/models/{name}", "/models/{name}/measurements", "/sparql", "/sparql/update", "/queries/{name}",
                 "/jobs/calibrate", "/jobs/compare", "/jobs/diagnose", "/jobs/add-effect", "/jobs/assemble", "/jobs/{job_id}/cancel"):
        assert path in paths
    assert "text/turtle" in paths["/models/{name}"]["put"]["requestBody"]["content"]
    # the statuses a route can answer are documented: reads need a token when reads are not open
    for path in ("/models", "/models/{name}", "/queries", "/queries/{name}", "/jobs", "/jobs/{job_id}", "/sparql"):
        assert {"401", "403"} <= set(paths[path]["get"]["responses"]), path
    assert "409" in paths["/jobs/add-effect"]["post"]["responses"]
    assert "413" in paths["/sparql"]["post"]["responses"]


def test_the_brick_report_of_a_model_is_served(client, auth, settings, store):
    assert client.put("/models/brick", content=REPORT_MODEL.encode(), headers={**auth, "Content-Type": "text/turtle"}).status_code == 201
    report = client.get("/models/brick/brick-report").json()
    assert report["official_ontology"] is False
    classes = {c["class_iri"].rsplit("#", 1)[1]: c for c in report["unaligned_classes"]}
    assert set(classes) == {"Chiller", "Supply_Air_Temprature_Setpoint"} and classes["Chiller"]["unaligned"] == 1
    assert report["points_without_unit"] == [REPORT_NAMESPACE + "sat"]
    assert client.get("/models/nope/brick-report").status_code == 404
    if not OFFICIAL_BRICK.is_file():
        pytest.skip(f"the official Brick.ttl is not at {OFFICIAL_BRICK} (../shared): the rest needs it")
    official = settings.model_copy(update={"brick_ontology": OFFICIAL_BRICK,  # a second service: its own data dir
                                           "data_dir": settings.data_dir.parent / "informed"})
    with TestClient(create_app(official, store=store)) as informed:
        report = informed.get("/models/brick/brick-report").json()
    classes = {c["class_iri"].rsplit("#", 1)[1]: c["needed"] for c in report["unaligned_classes"]}
    assert report["official_ontology"] is True and classes["Chiller"].startswith("official Brick, not in graphtwin's subset")
    assert classes["Supply_Air_Temprature_Setpoint"].startswith("not official Brick")


@pytest.mark.parametrize("fmt", [ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES, ox.RdfFormat.RDF_XML, ox.RdfFormat.JSON_LD])
def test_a_model_uploads_in_every_format_and_is_replaced(client, auth, store, fmt):
    triples = [ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(path=str(CASE_STUDY), format=ox.RdfFormat.TURTLE)]
    body = ox.serialize(triples, format=fmt)
    created = client.put("/models/copy", content=body, headers={**auth, "Content-Type": fmt.media_type})
    assert created.status_code == 201, created.text
    assert created.json()["triples"] == len(set(triples)) and not created.json()["replaced"] and created.json()["changed"]
    assert created.json()["assembly"] == {"complete": True, "problems": [], "notes": list(assemble(store, "copy").notes)}
    assert store.backend.triple_count(store.model_graph("copy")) == len(set(triples))
    replaced = client.put("/models/copy", content=body[: len(body)], headers={**auth, "Content-Type": fmt.media_type})
    assert replaced.status_code == 200 and replaced.json()["replaced"] and not replaced.json()["changed"]
    added = ox.Triple(ox.NamedNode("https://example.org/added"), ox.NamedNode("https://example.org/p"), ox.Literal("x"))
    edited = client.put("/models/copy", content=ox.serialize([*triples, added], format=fmt),
                        headers={**auth, "Content-Type": fmt.media_type})
    assert edited.status_code == 200 and edited.json()["changed"] and edited.json()["triples"] == len(set(triples)) + 1
    assert [m["name"] for m in client.get("/models").json()["data"]] == ["case", "copy"]
    info = client.get("/models/copy").json()
    assert info["triples"] == len(set(triples)) + 1 and info["inferred_triples"] > 0 and not info["assembled"]


def test_an_upload_that_does_not_assemble_is_stored_and_says_why(client, auth, store):
    """A misspelt class leaves the fan out: the upload is stored (201), and its answer says that the
    model is incomplete and why, before any data are sent (before: 201 and nothing else)."""
    body = CASE_STUDY.read_text(encoding="utf-8").replace("ex:supply_fan a s4bldg:Fan", "ex:supply_fan a s4bldg:Fann")
    created = client.put("/models/fann", content=body.encode(), headers={**auth, "Content-Type": "text/turtle"})
    assert created.status_code == 201 and store.has_model("fann")
    check = created.json()["assembly"]
    assert not check["complete"] and check["problems"][0].startswith("supply_fan: its class https://saref.etsi.org/saref4bldg/Fann")
    lines = body.splitlines()
    line = next(i for i, text in enumerate(lines, 1) if "s4bldg:Fann" in text)
    column = lines[line - 1].index("s4bldg:Fann") + 1
    assert check["problems"][0].endswith(f"(did you mean https://saref.etsi.org/saref4bldg/Fan?) "
                                         f"(model fann, line {line}, column {column})")


def test_malformed_rdf_is_refused_with_line_and_column_and_changes_nothing(client, auth, store, snapshot):
    before = snapshot(store)
    broken = "@prefix ex: <https://example.org/x#> .\nex:a ex:b ex:c .\nex:d zz:e ex:f .\n"
    for name in ("case", "new"):
        response = client.put(f"/models/{name}", content=broken, headers={**auth, "Content-Type": "text/turtle"})
        assert response.status_code == 400
        assert response.json()["line"] == 3 and response.json()["column"] >= 1 and "zz" in response.json()["detail"]
    assert snapshot(store) == before
    assert client.put("/models/x", content=b"<a> <b> <c> .", headers={**auth, "Content-Type": "image/png"}).status_code == 415
    # what curl --data-binary @model.ttl sends without -H Content-Type: read as Turtle, as an absent type is
    curl = client.put("/models/curl", content=CASE_STUDY.read_bytes(),
                      headers={**auth, "Content-Type": "application/x-www-form-urlencoded"})
    assert curl.status_code == 201 and curl.json()["assembly"]["complete"]
    before = snapshot(store)
    assert client.put("/models/bad name", content=b"", headers=auth).status_code == 422
    assert snapshot(store) == before


def test_oversize_uploads_are_refused_with_413(client, auth, store, snapshot, settings):
    before = snapshot(store)
    too_big = b"#" * (settings.max_upload_bytes + 1)
    assert client.put("/models/big", content=too_big, headers={**auth, "Content-Type": "text/turtle"}).status_code == 413
    assert _upload_csv(client, auth, too_big.decode()).status_code == 413
    assert snapshot(store) == before and not list(settings.measurements_dir.rglob("*.csv"))


def test_writes_need_the_token_and_reads_can_be_closed(tmp_path, store):
    body = CASE_STUDY.read_bytes()
    with TestClient(create_app(Settings(data_dir=tmp_path / "a", token="secret-token-1"), store=store)) as client:
        assert client.put("/models/x", content=body).status_code == 401
        wrong = client.put("/models/x", content=body, headers={"Authorization": "Bearer nope-nope-nope"})
        assert wrong.status_code == 401 and "Bearer" in wrong.headers["www-authenticate"]
        assert client.post("/jobs/assemble", json={"model": "case"}).status_code == 401
        assert client.get("/models").status_code == 200
    with TestClient(create_app(Settings(data_dir=tmp_path / "b"), store=store)) as client:
        refused = client.put("/models/x", content=body, headers={"Authorization": "Bearer anything-at-all"})
        assert refused.status_code == 403 and "GRAPHTWIN_TOKEN" in refused.json()["detail"]
    closed = Settings(data_dir=tmp_path / "c", token="secret-token-1", open_reads=False)
    with TestClient(create_app(closed, store=store)) as client:
        assert client.get("/models").status_code == 401
        assert client.get("/sparql", params={"query": "ASK {}"}).status_code == 401
        assert client.get("/models", headers={"Authorization": "Bearer secret-token-1"}).status_code == 200
        assert client.get("/health").status_code == 200
    assert "secret-token-1" not in repr(closed)


# ---------------------------------------------------------------------- measurements
def test_measurements_are_validated_kept_and_listed(client, auth, case_csv, settings, store):
    response = _upload_csv(client, auth, case_csv.read_text())
    assert response.status_code == 201, response.text
    info = response.json()
    assert info["rows"] == len(_csv_rows(case_csv)) - 1 and info["step_s"] == 600.0
    assert set(info["columns"]) == set(series_specs(assemble(store, "case")))
    assert set(info["columns"].values()) <= set(_csv_rows(case_csv)[0][1:])
    assert (settings.measurements_dir / "case" / f"{info['id']}.csv").read_text() == case_csv.read_text()
    listed = client.get("/models/case/measurements").json()
    assert [m["id"] for m in listed["data"]] == [info["id"]]
    assert client.get("/models/case").json()["measurements"] == [info["id"]]
    assert info["new"] and info["sha256"] == hashlib.sha256(case_csv.read_text().encode()).hexdigest()
    again = _upload_csv(client, auth, case_csv.read_text())  # the same file: its first id, nothing added
    assert again.status_code == 200 and again.json()["id"] == info["id"] and not again.json()["new"]
    assert client.get("/models/case").json()["measurements"] == [info["id"]]
    other = _upload_csv(client, auth, case_csv.read_text().replace(",", ", ", 1))
    assert other.status_code == 201 and other.json()["id"] != info["id"]


def _bad_csv(case_csv, problem: str) -> str:
    rows = _csv_rows(case_csv)
    if problem == "unknown column":
        rows = [row + [value] for row, value in zip(rows, ["mystery_sensor"] + ["1.0"] * (len(rows) - 1))]
    elif problem == "extra field":
        rows[3].append("1.0")
    elif problem == "NaN":
        rows[1][3] = "NaN"
    elif problem == "unsorted":
        rows[5], rows[6] = rows[6], rows[5]
    elif problem == "duplicate":
        rows[6][0] = rows[5][0]
    elif problem == "not a number":
        rows[4][2] = "warm"
    elif problem == "glitched stamp":  # as BMS exports write one: the last row in year 9999
        rows[-1][0] = "9999-12-31T23:50:00"
    return _csv_text(rows)


@pytest.mark.parametrize("problem, expected", [
    ("extra field", "line 4: "), ("NaN", "without a value"), ("unsorted", "before the previous one"),
    ("duplicate", "duplicate time stamp"), ("not a number", "'warm' is not a number"),
    ("glitched stamp", "lies outside the years 1970–2100"),
])
def test_bad_measurements_are_refused_with_every_problem_and_change_nothing(client, auth, case_csv, store, snapshot,
                                                                           settings, problem, expected):
    before = snapshot(store)
    response = _upload_csv(client, auth, _bad_csv(case_csv, problem))
    assert response.status_code == 422
    assert any(expected in p for p in response.json()["problems"]), response.json()
    assert snapshot(store) == before and not list(settings.measurements_dir.rglob("*.csv"))


def test_an_upload_a_stopped_service_left_half_written_is_removed_at_start(settings, store):
    """A service killed while it validated an upload leaves its temporary file; the next start removes
    it (a kept upload and its description stay)."""
    folder = settings.measurements_dir / "case"
    folder.mkdir(parents=True)
    (folder / ".upload-abc123.csv").write_text("time,x\n")
    (folder / "0123456789abcdef.csv").write_text("time,x\n")
    (folder / "0123456789abcdef.json").write_text("{}")
    with TestClient(create_app(settings, store=store)):
        assert sorted(p.name for p in folder.iterdir()) == ["0123456789abcdef.csv", "0123456789abcdef.json"]


def test_a_model_and_an_upload_are_deleted_and_runs_stay(client, auth, case_csv, store, settings):
    upload = _upload_csv(client, auth, case_csv.read_text()).json()["id"]
    store.write_graph(store.run_graph("case-point-00000000"), [ox.Triple(ox.NamedNode(EX + "r"), ox.NamedNode(EX + "p"), ox.Literal("run"))])
    assert client.delete(f"/models/case/measurements/{upload}").status_code == 401  # writes need the token
    # a stored run made with the upload: refused naming it (its report page plots the upload), unless forced
    from service.graph.namespaces import GT

    store.write_graph(store.run_graph("case-point-11111111"), [ox.Triple(
        ox.NamedNode("https://w3id.org/graphtwin/resource/run/case-point-11111111"), GT.dataSource,
        ox.Literal(f"{upload}.csv"))])
    used = client.delete(f"/models/case/measurements/{upload}", headers=auth)
    assert used.status_code == 409 and "case-point-11111111" in used.json()["detail"], used.json()
    assert client.get("/models/case/measurements").json()["count"] == 1
    assert client.delete(f"/models/case/measurements/{upload}", headers=auth, params={"force": "true"}).status_code == 204
    assert client.get("/models/case/measurements").json()["count"] == 0
    assert not list(settings.measurements_dir.rglob(f"{upload}.*"))
    assert client.delete(f"/models/case/measurements/{upload}", headers=auth).status_code == 404
    assert client.delete("/models/../measurements/0123456789abcdef", headers=auth).status_code == 404
    assert client.delete("/models/" + "m" * 300 + "/measurements/0", headers=auth).status_code == 404  # was a 500
    store.write_graph(store.assembly_graph("case"), [ox.Triple(ox.NamedNode(EX + "c"), ox.NamedNode(EX + "p"), ox.Literal("x"))])
    assert client.delete("/models/case", headers=auth).status_code == 204
    graphs = store.backend.graphs()
    assert not {store.model_graph("case"), store.inferred_graph("case"), store.assembly_graph("case")} & set(graphs)
    assert store.run_graph("case-point-00000000") in graphs
    assert client.get("/models/case").status_code == 404 and client.delete("/models/case", headers=auth).status_code == 404


def test_a_deleted_models_uploads_stay_listed(client, auth, case_csv):
    """"Runs and uploads stay" (docs/http.md), but the listing answered 404 once the model was gone."""
    upload = _upload_csv(client, auth, case_csv.read_text()).json()["id"]
    assert client.delete("/models/case", headers=auth).status_code == 204
    listed = client.get("/models/case/measurements")
    assert listed.status_code == 200 and [u["id"] for u in listed.json()["data"]] == [upload]
    assert client.get("/models/never/measurements").status_code == 404


def test_columns_no_device_claims_are_a_warning_as_in_the_cli(client, auth, case_csv):
    """A BMS export has more columns than the model reads (both real files in ../shared do)."""
    response = _upload_csv(client, auth, _bad_csv(case_csv, "unknown column"))
    assert response.status_code == 201, response.text
    assert "columns no device of the model claims: mystery_sensor (an operating filter may read them)" in response.json()["warnings"]


def test_measurements_sent_as_a_multipart_form_are_refused_saying_how_to_send_them(client, auth, case_csv, store, snapshot):
    """``curl -F file=@data.csv`` had been read as a CSV whose first line is the form's boundary."""
    before = snapshot(store)
    response = client.post("/models/case/measurements", headers=auth,
                           files={"file": ("data.csv", case_csv.read_bytes(), "text/csv")})
    assert response.status_code == 415, response.text
    assert "--data-binary @data.csv" in response.json()["detail"], response.json()
    assert snapshot(store) == before


def test_a_long_gap_is_accepted_when_asked(client, auth, case_csv):
    response = _upload_csv(client, auth, _bad_csv(case_csv, "NaN"), allow_gaps="true")
    assert response.status_code == 201 and response.json()["rows"] == len(_csv_rows(case_csv)) - 1


def test_measurements_in_a_unit_of_the_wrong_dimension_are_refused(client, auth, case_csv, store, snapshot):
    wrong = CASE_STUDY.read_text().replace(
        'saref:isMeasuredIn unit:DEG_C ;\n    gt:timeSeriesId "fan_inlet_air_temperature"',
        'saref:isMeasuredIn unit:W ;\n    gt:timeSeriesId "fan_inlet_air_temperature"')
    assert client.put("/models/wrong", content=wrong, headers={**auth, "Content-Type": "text/turtle"}).status_code == 201
    before = snapshot(store)
    response = _upload_csv(client, auth, case_csv.read_text(), model="wrong")
    assert response.status_code == 422
    assert any("fan_inlet_air_temperature" in p for p in response.json()["problems"]), response.json()
    assert response.json()["detail"].startswith("the measurements do not fit model wrong: ")  # the cause, not only its place
    assert snapshot(store) == before
    assert _upload_csv(client, auth, case_csv.read_text(), model="nowhere").status_code == 404


# ---------------------------------------------------------------------- SPARQL
def test_sparql_select_by_get_and_post_in_every_result_format(client):
    query = "SELECT ?g (COUNT(*) AS ?n) WHERE { GRAPH ?g { ?s ?p ?o } } GROUP BY ?g ORDER BY ?g"
    rows = _rows(client.get("/sparql", params={"query": query}))
    graphs = {r["g"]["value"]: int(r["n"]["value"]) for r in rows}
    assert len(graphs) >= 3 and all(n > 0 for n in graphs.values())
    assert _rows(client.post("/sparql", data={"query": query})) == rows
    assert _rows(client.post("/sparql", content=query, headers={"Content-Type": "application/sparql-query"})) == rows
    as_csv = client.get("/sparql", params={"query": query}, headers={"Accept": "text/csv"})
    assert as_csv.headers["content-type"].startswith("text/csv")
    assert as_csv.text.splitlines()[0] == "g,n" and len(as_csv.text.splitlines()) == len(rows) + 1
    as_tsv = client.get("/sparql", params={"query": query}, headers={"Accept": "text/tab-separated-values;q=0.9, text/html;q=0.1"})
    assert as_tsv.text.splitlines()[0] == "?g\t?n" and as_tsv.text.splitlines()[1].startswith("<")
    union = _rows(client.get("/sparql", params={"query": COUNT_MODEL, "union-default-graph": "true"}))
    assert int(union[0]["n"]["value"]) == sum(graphs.values())
    one = next(iter(graphs))
    scoped = _rows(client.get("/sparql", params={"query": COUNT_MODEL, "default-graph-uri": one}))
    assert int(scoped[0]["n"]["value"]) == graphs[one]


def test_rdf_12_triple_terms_in_select_results_come_back_in_every_format(client):
    query = ("SELECT ?t WHERE { BIND(TRIPLE(<urn:s>, <urn:p>, TRIPLE(<urn:a>, <urn:b>, \"x\"@en)) AS ?t) }")
    [row] = _rows(client.get("/sparql", params={"query": query}))
    assert row["t"]["type"] == "triple"
    nested = row["t"]["value"]["object"]["value"]
    assert (row["t"]["value"]["subject"]["value"], nested["object"]) == ("urn:s", {"type": "literal", "value": "x", "xml:lang": "en"})
    as_tsv = client.get("/sparql", params={"query": query}, headers={"Accept": "text/tab-separated-values"})
    assert as_tsv.text.splitlines()[1] == '<<( <urn:s> <urn:p> <<( <urn:a> <urn:b> "x"@en )>> )>>'
    for media in ("application/sparql-results+xml", "text/csv"):
        assert client.get("/sparql", params={"query": query}, headers={"Accept": media}).status_code == 200, media


def test_sparql_construct_and_ask(client):
    construct = "CONSTRUCT { ?s ?p ?o } WHERE { GRAPH ?g { ?s ?p ?o } } LIMIT 7"
    turtle = client.get("/sparql", params={"query": construct})
    assert turtle.headers["content-type"].startswith("text/turtle")
    assert len(list(ox.parse(turtle.content, format=ox.RdfFormat.TURTLE))) == 7
    nt = client.get("/sparql", params={"query": construct}, headers={"Accept": "application/n-triples"})
    assert len(nt.text.strip().splitlines()) == 7
    ask = client.get("/sparql", params={"query": f"ASK {{ GRAPH ?g {{ <{EX}supply_fan> ?p ?o }} }}"})
    assert ask.json()["boolean"] is True


def test_bad_sparql_requests_get_their_status_and_change_nothing(client, auth, store, snapshot, settings):
    before = snapshot(store)
    assert len(before) > settings.max_result_rows
    assert client.get("/sparql", params={"query": "SELECT ?x WHERE { ?x"}).status_code == 400
    assert client.get("/sparql").status_code == 400
    unprefixed = client.get("/sparql", params={"query": "SELECT ?x WHERE { ?x a s4bldg:Fan }"})
    assert unprefixed.status_code == 400 and unprefixed.json()["detail"].endswith(
        "the prefix s4bldg: is not declared (add PREFIX s4bldg: <https://saref.etsi.org/saref4bldg/>)")
    update = "PREFIX ex: <https://example.org/x#>\nINSERT DATA { ex:a ex:b ex:c }"
    assert client.get("/sparql", params={"query": update}).status_code == 403
    assert client.post("/sparql", data={"query": update}, headers=auth).status_code == 403
    assert client.post("/sparql", content=update, headers={"Content-Type": "application/sparql-query"}).status_code == 403
    assert client.post("/sparql", content="ASK {}", headers={"Content-Type": "text/plain"}).status_code == 415
    assert client.get("/sparql", params={"query": "ASK {}"}, headers={"Accept": "image/png"}).status_code == 406
    assert client.post("/sparql/update", content=update, headers={"Content-Type": "application/sparql-update"}).status_code == 401
    bad = client.post("/sparql/update", content="INSERT DATA { <a> ", headers={**auth, "Content-Type": "application/sparql-update"})
    assert bad.status_code == 400
    service = "SELECT * WHERE { SERVICE <http://127.0.0.1:9/sparql> { ?s ?p ?o } }"
    refused = client.get("/sparql", params={"query": service})
    assert refused.status_code == 403 and "SERVICE" in refused.json()["detail"]
    named = client.get("/sparql", params={"query": 'SELECT * WHERE { ?service ?p "SERVICE" } LIMIT 1'})
    assert named.status_code == 200  # the word as a variable or a literal is no federated query
    headers = {**auth, "Content-Type": "application/sparql-update"}
    for keyword, fetching in [
        ("LOAD", "LOAD <http://127.0.0.1:9/x.nt> INTO GRAPH <https://example.org/g>"),
        ("SERVICE", "INSERT { GRAPH <https://example.org/g> { ?s ?p ?o } } WHERE { SERVICE <http://127.0.0.1:9/q> { ?s ?p ?o } }"),
    ]:
        refused = client.post("/sparql/update", content=fetching, headers=headers)
        assert refused.status_code == 403 and refused.json()["detail"].startswith(f"{keyword} is refused here")
    failing = client.post("/sparql/update", content="DROP GRAPH <https://example.org/absent>", headers=headers)
    assert failing.status_code == 400 and "does not exist" in failing.json()["detail"]
    unicode_prefix = "PREFIX é: <http://example.org/> CONSTRUCT { é:a é:b ?x } WHERE { BIND(1 AS ?x) }"
    assert client.get("/sparql", params={"query": unicode_prefix}, headers={"Accept": "text/turtle"}).status_code == 200
    too_many = client.get("/sparql", params={"query": "SELECT * WHERE { GRAPH ?g { ?s ?p ?o } }"})
    assert too_many.status_code == 422 and "LIMIT" in too_many.json()["detail"]
    assert snapshot(store) == before


def test_accept_q0_refuses_a_type_a_wildcard_admits_and_a_version_prologue_is_read(client):
    """RFC 9110: ``q=0`` means not acceptable, also beside ``*/*``; SPARQL 1.2's ``VERSION`` is prologue."""
    ask = client.get("/sparql", params={"query": "ASK {}"}, headers={"Accept": "application/sparql-results+json;q=0, */*"})
    assert ask.status_code == 200 and ask.headers["content-type"].startswith("application/sparql-results+xml")
    construct = "CONSTRUCT { <https://example.org/a> <https://example.org/b> <https://example.org/c> } WHERE {}"
    answer = client.get("/sparql", params={"query": construct}, headers={"Accept": "text/turtle;q=0, */*;q=0.1"})
    assert answer.status_code == 200 and not answer.headers["content-type"].startswith("text/turtle")
    assert client.get("/sparql", params={"query": "ASK {}"}, headers={
        "Accept": "application/sparql-results+json;q=0, application/*;q=0"}).status_code == 406
    versioned = client.get("/sparql", params={"query": 'VERSION "1.2" ' + construct})
    assert versioned.status_code == 200 and "https://example.org/c" in versioned.text
    assert client.get("/sparql", params={"query": "VERSION '1.2' ASK {}"}).json()["boolean"] is True


def test_sparql_update_with_the_token_writes(client, auth):
    update = "INSERT DATA { GRAPH <https://example.org/g> { <https://example.org/a> <https://example.org/b> 1 } }"
    response = client.post("/sparql/update", data={"update": update}, headers=auth)
    assert response.status_code == 204
    ask = "ASK { GRAPH <https://example.org/g> { <https://example.org/a> ?p 1 } }"
    assert client.get("/sparql", params={"query": ask}).json()["boolean"] is True


def test_an_update_to_a_model_graph_derives_its_inferences_again(client, auth, store):
    """A sensor added with the SAREF v3 spelling is matched only through what the alignment derives;
    the assembly, which described the model before, goes as it does on a new upload."""
    sensor, fan_flow = "https://example.org/added_sensor", f"<{EX}supply_air_flow>"
    update = (f"INSERT DATA {{ GRAPH {store.model_graph('case')} {{ <{sensor}> "
              f"<https://saref.etsi.org/core/measuresProperty> {fan_flow} }} }}")
    other = "INSERT DATA { GRAPH <https://example.org/g> { <https://example.org/a> <https://example.org/b> 1 } }"
    store.write_graph(store.assembly_graph("case"), [ox.Triple(ox.NamedNode(EX + "c"), ox.NamedNode(EX + "p"), ox.Literal("x"))])
    written = []
    write_graphs = store.write_graphs
    store.write_graphs = lambda graphs: (written.extend(graphs), write_graphs(graphs))[1]
    assert client.post("/sparql/update", data={"update": other}, headers=auth).status_code == 204
    assert written == []  # no model graph named
    assert client.post("/sparql/update", data={"update": update}, headers=auth).status_code == 204
    assert written == [store.inferred_graph("case"), store.assembly_graph("case")]
    ask = (f"ASK {{ GRAPH {store.inferred_graph('case')} {{ <{sensor}> <https://saref.etsi.org/core/observes> "
           f"{fan_flow} }} }}")
    assert client.get("/sparql", params={"query": ask}).json()["boolean"] is True
    assert store.assembly_graph("case") not in store.backend.graphs()
    assert not client.get("/models/case").json()["assembled"]


def test_a_model_graph_dropped_by_an_update_takes_its_inferences_and_a_graph_no_model_can_name_is_none(client, auth, store):
    assert client.put("/models/gone", content=CASE_STUDY.read_bytes(), headers=auth).status_code == 201
    assert store.inferred_graph("gone") in store.backend.graphs()
    assert client.post("/sparql/update", data={"update": f"DROP GRAPH {store.model_graph('gone')}"}, headers=auth).status_code == 204
    assert store.inferred_graph("gone") not in store.backend.graphs() and "gone" not in store.models()
    odd = "https://w3id.org/graphtwin/resource/graph/model/a/b"  # under the models' prefix, no model's name
    insert = f"INSERT DATA {{ GRAPH <{odd}> {{ <https://example.org/a> <https://example.org/b> 1 }} }}"
    assert client.post("/sparql/update", data={"update": insert}, headers=auth).status_code == 204
    listed = client.get("/models")
    assert listed.status_code == 200 and [m["name"] for m in listed.json()["data"]] == ["case"]
    again = "INSERT DATA { GRAPH <https://example.org/g> { <https://example.org/a> <https://example.org/b> 2 } }"
    assert client.post("/sparql/update", data={"update": again}, headers=auth).status_code == 204  # was a 500 after it


def test_an_update_of_a_graph_graphtwin_maintains_is_refused_and_one_of_every_graph_leaves_them_whole(client, auth, store):
    """``DROP GRAPH`` of the ontologies had left every model unassemblable until a restart (204); now
    a maintained graph named is 403 with nothing changed, and an update that can write any graph
    (``DROP ALL``) runs, after which the ontologies and alignment rules are written again."""
    from service.graph.store import ALIGNMENT_RULES_GRAPH, ONTOLOGY_GRAPH

    held = {g: set(store.graph_triples(g)) for g in (ONTOLOGY_GRAPH, ALIGNMENT_RULES_GRAPH)}
    for update in (f"DROP GRAPH {ONTOLOGY_GRAPH}",
                   f"DELETE WHERE {{ GRAPH {ALIGNMENT_RULES_GRAPH} {{ ?s ?p ?o }} }}"):
        refused = client.post("/sparql/update", data={"update": update}, headers=auth)
        assert refused.status_code == 403 and "graphtwin maintains" in refused.json()["detail"], refused.json()
    assert {g: set(store.graph_triples(g)) for g in held} == held and store.models() == ["case"]
    assert client.post("/sparql/update", data={"update": "DROP ALL"}, headers=auth).status_code == 204
    assert {g: set(store.graph_triples(g)) for g in held} == held and store.models() == []
    assert client.put("/models/again", content=CASE_STUDY.read_bytes(), headers=auth).json()["assembly"]["complete"]
    # a syntax error says where, not the parser's character classes
    broken = client.post("/sparql/update", data={"update": "INSERT DATA { <a> <b> }"}, headers=auth)
    assert broken.status_code == 400 and broken.json()["detail"].startswith("SPARQL Update syntax error at line 1, column")


def test_a_model_name_longer_than_a_file_name_can_be_is_refused(client, auth):
    response = client.put("/models/" + "m" * 129, content=CASE_STUDY.read_bytes(), headers=auth)
    assert response.status_code == 422 and "128 characters at most" in response.json()["detail"]
    assert client.put("/models/" + "m" * 128, content=CASE_STUDY.read_bytes(), headers=auth).status_code == 201


def test_a_query_over_the_time_limit_gets_503(tmp_path, store, monkeypatch):
    release = threading.Event()
    monkeypatch.setattr(query_reader, "backend_answer", lambda *args: release.wait(30) and b"")
    try:
        with TestClient(create_app(Settings(data_dir=tmp_path, query_timeout_s=0.2), store=store)) as client:
            response = client.get("/sparql", params={"query": "ASK {}"})
            assert response.status_code == 503 and "time limit of 0.2 s" in response.json()["detail"]
    finally:
        release.set()


def test_a_failing_sparql_endpoint_gets_503(tmp_path, store, monkeypatch):
    def endpoint_fails(*args):
        raise StoreUnavailableError("SPARQL endpoint http://127.0.0.1:7878/query failed on the query (HTTP 500): boom")

    monkeypatch.setattr(query_reader, "backend_answer", endpoint_fails)
    with TestClient(create_app(Settings(data_dir=tmp_path, executor="threads"), store=store)) as client:
        response = client.get("/sparql", params={"query": "ASK {}"})
        assert response.status_code == 503 and "(HTTP 500): boom" in response.json()["detail"]


def test_every_route_answers_503_naming_an_unreachable_endpoint(tmp_path, auth):
    down = "http://127.0.0.1:9"  # the discard port: nothing listens
    settings = Settings(data_dir=tmp_path, token=auth["Authorization"].split()[-1], executor="threads", sparql_endpoint=down)
    with TestClient(create_app(settings)) as client:
        for response in (client.get("/models"), client.get("/models/m"),
                         client.put("/models/m", content=b"<urn:a> <urn:p> <urn:b> .",
                                    headers={**auth, "Content-Type": "application/n-triples"})):
            assert response.status_code == 503 and down in response.json()["detail"], response.text


def test_named_queries_are_listed_and_run_with_bindings(client):
    listed = {q["name"]: q for q in client.get("/queries").json()["data"]}
    assert "model" in listed["calibrated-parameters"]["variables"] and listed["flow-edges"]["description"]
    assert _rows(client.get("/queries/calibrated-parameters", params={"model": "case"})) == []
    edges = _rows(client.get("/queries/flow-edges", params={"dataset": "case"}))
    assert {e["kind"]["value"] for e in edges} == {"fluid", "heat"}
    link = _rows(client.get("/queries/measurement-link", params={"dataset": "case", "device": EX + "fan_power_meter"}))
    assert link[0]["series_id"]["value"] == "supply_fan_power"
    assert client.get("/queries/nope").status_code == 404
    assert client.get("/queries/flow-edges", params={"dataset": "nope"}).status_code == 404
    no_model = client.get("/queries/calibrated-parameters", params={"model": "nope"})
    assert no_model.status_code == 404 and "no model 'nope'" in no_model.json()["detail"] and "case" in no_model.json()["detail"]
    unknown = client.get("/queries/calibrated-parameters", params={"modle": "case"})
    assert unknown.status_code == 422 and "model" in unknown.json()["detail"]
    plus = client.get("/queries/calibrated-parameters?model=case+ValveLeakage")  # an added effect's version, '+' unescaped
    assert plus.status_code == 422 and "write 'case%2BValveLeakage'" in plus.json()["detail"]


def test_a_dropped_models_results_stay_queryable_by_its_name(client, store):
    """Only a name with neither a model nor a stored run is unknown: a dropped model's runs are kept."""
    run = ox.NamedNode("https://w3id.org/graphtwin/resource/run/r1")
    store.write_graph(store.run_graph("r1"), [ox.Triple(run, ox.NamedNode("https://w3id.org/graphtwin/ontology#forModel"),
                                                        ox.Literal("gone"))])
    assert not store.has_model("gone") and store.has_results("gone") and not store.has_results("nope")
    assert client.get("/queries/calibrated-parameters", params={"model": "gone"}).status_code == 200


def test_a_query_about_a_models_graphs_binds_them_from_model(client, store):
    """``model=NAME`` binds ?model_graph, ?inferred_graph and ?ontology_graph as the CLI's --model does:
    the misspelt class of one model is found there and not in the other's."""
    store.load_model("typo", (CASE_STUDY.read_text(encoding="utf-8")
                     + f"\n<{EX}heating_valve> a <https://saref.etsi.org/saref4bldg/Valv> .\n").encode())
    typo = _rows(client.get("/queries/undeclared-classes", params={"model": "typo"}))
    assert [row["class"]["value"] for row in typo] == ["https://saref.etsi.org/saref4bldg/Valv"]
    assert _rows(client.get("/queries/undeclared-classes", params={"model": "case"})) == []
    refused = client.get("/queries/flow-edges", params={"model": "case"})
    assert refused.status_code == 422 and "dataset=MODEL" in refused.json()["detail"]


# ---------------------------------------------------------------------- jobs
def test_job_requests_for_unknown_things_are_refused(client, auth, case_csv):
    upload = _upload_csv(client, auth, case_csv.read_text()).json()["id"]
    assert client.get("/jobs/0123456789abcdef0123456789abcdef").status_code == 404
    assert client.get("/jobs/../../etc").status_code == 404
    assert client.post("/jobs/0123456789abcdef0123456789abcdef/cancel", headers=auth).status_code == 404
    assert client.post("/jobs/assemble", json={"model": "nope"}, headers=auth).status_code == 404
    assert client.post("/jobs/calibrate", json={"model": "case", "measurements": "0000000000000000"}, headers=auth).status_code == 404
    bad_window = client.post("/jobs/calibrate", json={"model": "case", "measurements": upload, "train": "2026-01-12"}, headers=auth)
    assert bad_window.status_code == 422 and "START/END" in bad_window.json()["detail"]
    assert bad_window.json()["problems"] == ["body.train: Value error, window '2026-01-12': write START/END, "
                                             "e.g. 2026-01-12/2026-01-15T23:50"]
    bad_stamp = client.post("/jobs/calibrate", json={"model": "case", "measurements": upload,
                                                     "train": "2026-01-12/2026-13-45"}, headers=auth)
    assert bad_stamp.status_code == 422  # refused before a job is queued, naming the side
    assert "window '2026-01-12/2026-13-45', its end: time stamp '2026-13-45'" in bad_stamp.json()["detail"]
    reversed_window = client.post("/jobs/calibrate", json={"model": "case", "measurements": upload,
                                                           "train": "2026-01-12T10:00/2026-01-12T09:00"}, headers=auth)
    assert reversed_window.status_code == 422 and "the end is before the start" in reversed_window.json()["detail"]
    for seed in (-1, 2**64):
        bad_seed = client.post("/jobs/calibrate", json={"model": "case", "measurements": upload, "seed": seed}, headers=auth)
        assert bad_seed.status_code == 422 and "seed" in bad_seed.json()["detail"]
    effect = client.post("/jobs/add-effect", json={"model": "case", "effect": "Nope", "target": EX + "supply_fan"}, headers=auth)
    assert effect.status_code == 422 and "FanMotorHeat" in effect.json()["detail"]
    effect = client.post("/jobs/add-effect", json={"model": "case", "effect": "FanMotorHeat", "target": "supply_fan"},
                         headers=auth)  # a node's local name: named with its IRI, as at the command line
    assert effect.status_code == 422 and effect.json()["detail"].endswith(f"give its full IRI, e.g. {EX}supply_fan")
    assert client.post("/jobs/diagnose", json={"model": "case", "measurements": upload, "train": "/"}, headers=auth).status_code == 422
    misspelt = client.post("/jobs/calibrate", headers=auth, json={"model": "case", "measurements": upload, "start-from": "v0"})
    assert misspelt.status_code == 422 and "start-from" in misspelt.json()["detail"]  # not ignored
    condition = client.post("/jobs/calibrate", headers=auth, json={
        "model": "case", "measurements": upload, "only_when": ["fan speed = 1"]})
    assert condition.status_code == 422 and "expected COLUMN OP NUMBER" in condition.json()["detail"]
    for kind, windows in (("calibrate", {}), ("diagnose", {"train": "/2026-01-12T11:50", "test": "2026-01-12T12:00/"})):
        start = client.post(f"/jobs/{kind}", headers=auth, json={
            "model": "case", "measurements": upload, "start_from": "v0", **windows})
        assert start.status_code == 404 and start.json()["detail"] == "no model 'v0'; known: case", kind
    assert client.get("/jobs").json()["count"] == 0


def test_assemble_and_add_effect_jobs_write_their_results(client, auth, store, wait_job):
    submitted = client.post("/jobs/assemble", json={"model": "case"}, headers=auth)
    assert submitted.status_code == 202 and submitted.headers["location"] == f"/jobs/{submitted.json()['id']}"
    job = wait_job(client, submitted.json()["id"])
    assert job["status"] == "succeeded", job
    assert len(job["result"]["targets"]) == len(assemble(store, "case").targets)
    assert client.get("/models/case").json()["assembled"]
    assert [p["message"] for p in job["progress"]][-1] == "results written to the store"

    base = store.backend.triple_count(store.model_graph("case"))
    job = wait_job(client, client.post("/jobs/add-effect", headers=auth, json={
        "model": "case", "effect": "ValveLeakage", "target": EX + "heating_valve"}).json()["id"])
    assert job["status"] == "succeeded", job
    assert job["result"]["model"] == "case+ValveLeakage" and job["links"]["model"] == "/models/case+ValveLeakage"
    assert store.backend.triple_count(store.model_graph("case")) == base
    effects = _rows(client.get("/queries/applied-effects", params={"dataset": "case+ValveLeakage"}))
    assert [e["node"]["value"] for e in effects] == [EX + "heating_valve"]
    assert any(c.signature.id == "ValveLeakage" for c in assemble(store, "case+ValveLeakage").components.values())
    derived = store.query("PREFIX gt: <https://w3id.org/graphtwin/ontology#> SELECT ?base WHERE { ?a gt:derivedFromModel ?base }",
                          default_graph=[store.assembly_graph("case+ValveLeakage")])
    assert [r["base"].value for r in derived] == ["case"]
    # the same effect at another node would overwrite that version: refused, the version kept
    elsewhere = client.post("/jobs/add-effect", headers=auth, json={
        "model": "case", "effect": "ValveLeakage", "target": EX + "supply_fan"})
    assert elsewhere.status_code == 409 and "ValveLeakage at " + EX + "heating_valve" in elsewhere.json()["detail"]
    assert [e["node"]["value"] for e in _rows(client.get("/queries/applied-effects", params={"dataset": "case+ValveLeakage"}))] == [EX + "heating_valve"]
    again = wait_job(client, client.post("/jobs/add-effect", headers=auth, json={  # the same request again: idempotent
        "model": "case", "effect": "ValveLeakage", "target": EX + "heating_valve"}).json()["id"])
    assert again["status"] == "succeeded", again
    named = wait_job(client, client.post("/jobs/add-effect", headers=auth, json={
        "model": "case", "effect": "ValveLeakage", "target": EX + "heating_valve", "version": "case-leak"}).json()["id"])
    assert named["status"] == "succeeded" and named["result"]["model"] == "case-leak", named

    jobs_before = len(client.get("/jobs").json()["data"])
    refused = client.post("/jobs/add-effect", headers=auth, json={
        "model": "case", "effect": "FanMotorHeat", "target": EX + "heating_valve"})
    assert refused.status_code == 422 and "does not apply" in refused.json()["detail"]  # checked at submission
    assert len(client.get("/jobs").json()["data"]) == jobs_before and "case+FanMotorHeat" not in store.models()


def test_a_queued_job_is_cancelled_at_once_and_a_running_one_is_discarded(client, auth, store, wait_job):
    runner = client.app.state.graphtwin.runner
    started, release = threading.Event(), threading.Event()

    def blocking(job_store, request, context):
        started.set()
        release.wait(30)
        job_store.write_graph(job_store.assembly_graph(request.model), [
            ox.Triple(ox.NamedNode(EX + "x"), ox.NamedNode(EX + "y"), ox.Literal("z"))])
        return JobResult({"done": True})

    runner.kinds["assemble"] = JobKind(AssembleRequest, blocking)
    running = client.post("/jobs/assemble", json={"model": "case"}, headers=auth).json()
    assert started.wait(10)
    queued = client.post("/jobs/assemble", json={"model": "case"}, headers=auth).json()
    assert queued["status"] == "queued"
    cancelled = client.post(f"/jobs/{queued['id']}/cancel", headers=auth).json()
    assert cancelled["status"] == "cancelled"
    flagged = client.post(f"/jobs/{running['id']}/cancel", headers=auth).json()
    assert flagged["status"] == "running" and flagged["cancel_requested"]
    release.set()
    assert wait_job(client, running["id"])["status"] == "cancelled"
    assert store.assembly_graph("case") not in store.backend.graphs()
    assert client.post(f"/jobs/{running['id']}/cancel", headers=auth).status_code == 409


def test_job_state_survives_a_restart_and_interrupted_jobs_can_be_resubmitted(tmp_path, store, auth, wait_job):
    settings = Settings(data_dir=tmp_path / "service", token="test-token-0123456789", executor="threads")
    with TestClient(create_app(settings, store=store)) as client:
        finished = wait_job(client, client.post("/jobs/assemble", json={"model": "case"}, headers=auth).json()["id"])
    stale = JobRecord(id="ab" * 16, kind="assemble", params={"model": "case"}, status="running",
                      started="2026-01-01T00:00:00+00:00")
    JobRecords(settings.jobs_dir).save(stale)
    with TestClient(create_app(settings, store=store)) as client:
        again = client.get(f"/jobs/{finished['id']}").json()
        assert again["status"] == "succeeded" and again["result"] == finished["result"]
        interrupted = client.get(f"/jobs/{stale.id}").json()
        assert interrupted["status"] == "interrupted" and "resubmit" in interrupted["error"]
        resubmitted = client.post(f"/jobs/{stale.id}/resubmit", headers=auth)
        assert resubmitted.status_code == 202 and resubmitted.json()["resubmitted_from"] == stale.id
        assert wait_job(client, resubmitted.json()["id"])["status"] == "succeeded"


def test_a_job_whose_upload_is_gone_is_refused_at_resubmission_and_an_unknown_kind_names_the_kinds(tmp_path, store, auth):
    """Resubmitting a calibration whose upload was deleted had queued a job that then failed; a
    POST to a job kind that does not exist had been a bare 405."""
    settings = Settings(data_dir=tmp_path / "service", token="test-token-0123456789", executor="threads")
    gone = JobRecord(id="cd" * 16, kind="calibrate", params={"model": "case", "measurements": "0123456789abcdef"},
                     status="failed", started="2026-01-01T00:00:00+00:00")
    JobRecords(settings.jobs_dir).save(gone)
    with TestClient(create_app(settings, store=store)) as client:
        refused = client.post(f"/jobs/{gone.id}/resubmit", headers=auth)
        assert refused.status_code == 404 and "0123456789abcdef" in refused.json()["detail"], refused.json()
        assert client.get("/jobs").json()["count"] == 1  # nothing queued
        unknown = client.post("/jobs/simulate", headers=auth, json={"model": "case"})
        assert unknown.status_code == 404 and "/jobs/calibrate, /jobs/compare, /jobs/diagnose" in unknown.json()["detail"]


def test_a_body_that_is_no_json_is_refused_naming_where_it_breaks(client, auth):
    broken = client.post("/jobs/assemble", content=b'{"model": "case",\n "seed": }',
                         headers={**auth, "Content-Type": "application/json"})
    assert broken.status_code == 422
    assert broken.json()["detail"] == "the request is not valid: the body is not valid JSON at line 2, column 10: Expecting value"


def test_a_running_record_is_interrupted_when_the_app_starts(tmp_path):
    settings = Settings(data_dir=tmp_path / "service")
    JobRecords(settings.jobs_dir).save(JobRecord(id="cd" * 16, kind="calibrate", params={}, status="running"))
    with TestClient(create_app(settings)) as client:
        assert client.get(f"/jobs/{'cd' * 16}").json()["status"] == "interrupted"
    assert settings.store_path.is_dir()


@pytest.fixture
def roomy_client(settings, store):
    """The service admitting 20 reads of one client at once (a TestClient's requests all come from one address)."""
    roomy = settings.model_copy(update={"max_queries_per_client": 20, "query_queue": 20})
    with TestClient(create_app(roomy, store=store)) as client:
        yield client


def test_concurrent_queries_during_a_calibration_never_see_half_a_run(roomy_client, auth, store, case_csv, wait_job):
    client = roomy_client
    upload = _upload_csv(client, auth, case_csv.read_text()).json()["id"]
    n_estimates = len(assemble(store, "case").estimated_parameters)
    job = client.post("/jobs/calibrate", headers=auth, json={
        "model": "case", "measurements": upload, "train": "/2026-01-12T15:50", "test": "2026-01-12T16:00/",
        "only_when": ["supply_air_flow > 0"]}).json()
    done = threading.Event()
    statuses, seen = [], []
    lock = threading.Lock()

    def hammer():
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            last = done.is_set()
            response = client.post("/sparql", data={"query": RUNS_PER_GRAPH})
            with lock:
                statuses.append(response.status_code)
                if response.status_code == 200:
                    seen.extend((int(r["runs"]["value"]), int(r["estimates"]["value"])) for r in _rows(response))
            if last:
                return
            time.sleep(0.05)

    threads = [threading.Thread(target=hammer) for _ in range(20)]
    for thread in threads:
        thread.start()
    try:
        finished = wait_job(client, job["id"], timeout_s=90)
    finally:
        done.set()
        for thread in threads:
            thread.join(30)
    assert finished["status"] == "succeeded", finished
    assert finished["result"]["settings"]["only_when"] == ["supply_air_flow > 0"]  # the filter is the run's provenance
    assert len(statuses) >= 40 and set(statuses) == {200}
    assert seen and all(pair == (1, n_estimates) for pair in seen), set(seen)
    parameters = _rows(client.get("/queries/calibrated-parameters", params={"model": "case"}))
    assert len(parameters) == len(finished["result"]["parameters"]) == n_estimates
    assert {p["run"]["value"].rsplit("/", 1)[-1] for p in parameters} == {finished["result"]["run_id"]}
    assert finished["links"]["run_graph"] == store.run_graph(finished["result"]["run_id"]).value
    # a second version of the model, its fit started from the first one's
    assert client.put("/models/case_again", content=CASE_STUDY.read_bytes(), headers=auth).status_code == 201
    again = wait_job(client, client.post("/jobs/calibrate", headers=auth, json={
        "model": "case_again", "measurements": upload, "train": "/2026-01-12T15:50", "start_from": "case"}).json()["id"])
    assert again["status"] == "succeeded", again
    assert again["result"]["settings"]["start_from"] == {"model": "case", "runs": [p["run"]["value"] for p in parameters[:1]]}


def test_the_service_answers_the_same_on_a_remote_sparql_endpoint(endpoint_backend, tmp_path, auth):
    remote = GraphStore(endpoint_backend)
    with TestClient(create_app(Settings(data_dir=tmp_path, token="test-token-0123456789", max_result_rows=500),
                               store=remote)) as client:
        assert client.get("/health").json()["backend"] == "remote"
        assert client.put("/models/case", content=CASE_STUDY.read_bytes(), headers=auth).status_code == 201
        query = f"SELECT ?label ?missing WHERE {{ GRAPH ?g {{ <{EX}supply_fan> <http://www.w3.org/2000/01/rdf-schema#label> ?label }} }}"
        rows = _rows(client.get("/sparql", params={"query": query}))
        assert len(rows) == 1 and rows[0]["label"]["type"] == "literal"
        assert client.get("/sparql", params={"query": query}, headers={"Accept": "text/csv"}).text.splitlines()[0] == "label"
        link = _rows(client.get("/queries/measurement-link", params={"dataset": "case", "device": EX + "fan_power_meter"}))
        assert link[0]["series_id"]["value"] == "supply_fan_power"
        union = _rows(client.get("/sparql", params={"query": COUNT_MODEL, "union-default-graph": "true"}))
        assert int(union[0]["n"]["value"]) == sum(endpoint_backend.triple_count(g) for g in endpoint_backend.graphs())
        assert client.get("/sparql", params={"query": "SELECT * WHERE { GRAPH ?g { ?s ?p ?o } }"}).status_code == 422
        assert client.get("/sparql", params={"query": "SELECT ?x WHERE { ?x"}).status_code == 400
        triple_term = "SELECT ?t WHERE { BIND(TRIPLE(<urn:s>, <urn:p>, 1) AS ?t) }"
        as_tsv = client.get("/sparql", params={"query": triple_term}, headers={"Accept": "text/tab-separated-values"})
        assert as_tsv.text.splitlines()[1] == "<<( <urn:s> <urn:p> 1 )>>"


def test_settings_never_show_the_token():
    with pytest.raises(ValueError) as refused:
        Settings(token="seven77")
    assert "seven77" not in str(refused.value) and "8 non-blank characters" in str(refused.value)
    assert "a-long-secret" not in repr(Settings(token="a-long-secret"))


def test_a_bad_setting_is_named_by_its_variable_or_option(monkeypatch):
    from service.errors import InputError
    from service.settings import load_settings

    monkeypatch.setenv("GRAPHTWIN_TOKEN", "seven77")
    with pytest.raises(InputError) as refused:
        load_settings({"executor": "--executor"}, executor="dask://nowhere")
    message = str(refused.value)
    assert message.startswith("GRAPHTWIN_TOKEN: a token needs at least 8 non-blank characters")
    assert "--executor (GRAPHTWIN_EXECUTOR): executor 'dask://nowhere': give threads" in message
    assert "seven77" not in message and "pydantic" not in message


@pytest.mark.parametrize("kind, fields, expected", [
    ("calibrate", {"train": "2030-01-01/2030-01-02"}, "training window 2030-01-01T00:00 – 2030-01-02T00:00 lies outside "
                                                        "the data upload {upload}"),
    ("calibrate", {"method": "bayes", "gp_inputs": ["time", "supply_air_flw"]}, "supply_air_flw"),
    ("calibrate", {"gp_inputs": ["time", "supply_air_flow"]}, "a point calibration has no discrepancy"),
    ("calibrate", {"gp_inputs": ["time"]}, "a point calibration has no discrepancy"),
    ("calibrate", {"only_when": ["no_such_column > 1"]}, "no_such_column"),
    ("diagnose", {"train": "/2026-01-12T15:50", "test": "2026-01-12T16:00/2026-01-12T16:30"}, "at least 12 are needed"),
])
def test_what_a_fit_would_refuse_is_refused_at_submission(client, auth, case_csv, kind, fields, expected):
    """A window outside the data, an unknown GP input or column, a test window too short: 422 naming
    the upload (not the server's path), and no job queued (before, 202 and a job that failed later)."""
    upload = _upload_csv(client, auth, case_csv.read_text()).json()["id"]
    body = {"model": "case", "measurements": upload, "train": "/2026-01-12T15:50", "test": "2026-01-12T16:00/", **fields}
    refused = client.post(f"/jobs/{kind}", headers=auth, json=body)
    assert refused.status_code == 422, refused.json()
    assert expected.format(upload=upload) in refused.json()["detail"] and "/measurements/" not in refused.json()["detail"]
    assert client.get("/jobs").json()["count"] == 0


def test_a_second_service_on_the_same_data_directory_refuses_to_start_and_touches_nothing(settings, store):
    """A second `graphtwin serve` on a live service's data directory failed to bind its port, but on
    the way marked the live service's running job interrupted on disk (with an external store nothing
    else stopped it)."""
    with TestClient(create_app(settings, store=store)):
        running = JobRecord(id="ef" * 16, kind="assemble", params={"model": "case"}, status="running")
        JobRecords(settings.jobs_dir).save(running)
        with pytest.raises(StoreInUseError, match=r"is in use by graphtwin serve \(pid \d+\): one graphtwin serve per folder"):
            create_app(settings, store=GraphStore.embedded(None))
        assert JobRecords(settings.jobs_dir).load(running.id).status == "running"
    with TestClient(create_app(settings, store=store)):  # the first one's stop released the directory
        assert JobRecords(settings.jobs_dir).load(running.id).status == "interrupted"


def test_a_write_without_its_token_and_an_oversize_body_are_refused_before_the_body_is_read(client, auth, settings):
    """A 200 MiB JSON body to /jobs/calibrate without a token was buffered and parsed for 9 s before
    its 401; a 48 MiB query of comment lines was read and parsed. Now the token is checked and the
    body held to its route's limit before the body is read (a body that is no JSON at all shows it:
    it is refused for the token or its size, not for its syntax)."""
    junk = b"{" * (settings.max_request_bytes + 1)
    refused = client.post("/jobs/calibrate", content=junk, headers={"Content-Type": "application/json"})
    assert refused.status_code == 401 and "bearer token" in refused.json()["detail"]
    too_big = client.post("/jobs/calibrate", content=junk, headers={**auth, "Content-Type": "application/json"})
    assert too_big.status_code == 413 and f"the limit here is {settings.max_request_bytes}" in too_big.json()["detail"]
    query = b"#" * (settings.max_query_bytes + 1) + b"\nASK {}"
    assert client.post("/sparql", content=query, headers={"Content-Type": "application/sparql-query"}).status_code == 413
    ask = client.post("/sparql", content=b"ASK {}", headers={"Content-Type": "application/sparql-query"})
    assert ask.status_code == 200 and ask.json()["boolean"] is True
    assert client.put("/models/x", content=b"#" * 10, headers={"Content-Type": "text/turtle"}).status_code == 401


def test_an_uploads_first_and_last_stamps_are_given_as_a_window_takes_them_back(client, auth, case_csv, store, tmp_path):
    """Stamps with a UTC offset are read as UTC; the upload answered "2026-03-02T05:00:00" without one,
    which a window then refused ("give it with an offset too"): they carry Z now, naive ones nothing."""
    naive = _upload_csv(client, auth, case_csv.read_text()).json()
    assert not naive["start"].endswith("Z") and naive["start"].startswith("2026-01-12T00:00")
    lines = case_csv.read_text().splitlines()
    offset = [lines[0]] + [line.replace(",", "-05:00,", 1) for line in lines[1:]]
    stamped = _upload_csv(client, auth, "\n".join(offset) + "\n").json()
    assert stamped["start"] == "2026-01-12T05:00:00Z", stamped
    from service.data.model_series import read_model_data
    from service.model.assembly import assemble

    path = tmp_path / "offset.csv"
    path.write_text("\n".join(offset) + "\n")
    window = read_model_data(assemble(store, "case"), path).window(stamped["start"], stamped["end"])
    assert window == slice(0, stamped["rows"])  # a window takes them as they are: the whole upload
