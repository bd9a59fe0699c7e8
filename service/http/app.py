"""The HTTP service: building models, measurements, SPARQL and jobs (FastAPI; OpenAPI at ``/docs``).

``create_app(settings)`` builds the app; ``graphtwin serve`` runs it with uvicorn. Resources:

* ``PUT /models/{name}``: upload or replace a building model (Turtle, N-Triples, RDF/XML, JSON-LD,
  chosen by ``Content-Type``; Turtle when absent) into its named graph; malformed RDF → 400 naming
  the line and column, the store unchanged. ``GET /models``, ``GET /models/{name}``.
* ``POST /models/{name}/measurements``: a measurement CSV, validated against the assembled model
  (every problem at once → 422 with ``problems``: columns no device claims, non-numbers, duplicate or
  unsorted time stamps, units of the wrong dimension, values missing where a gap is too long to fill
  unless ``allow_gaps=true``), kept as ``<data dir>/measurements/<model>/<id>.csv``.
* ``GET|POST /sparql``: SPARQL 1.1 Protocol queries (``query`` parameter or form field, or an
  ``application/sparql-query`` body; ``default-graph-uri``; ``union-default-graph=true`` queries
  every named graph as the default graph). Results by ``Accept``: SPARQL JSON (default), XML, CSV,
  TSV; graphs (CONSTRUCT, DESCRIBE) as Turtle (default), N-Triples, RDF/XML, JSON-LD. An update
  sent here → 403, so is a ``SERVICE`` clause (the server would fetch other URLs on the caller's
  behalf), a syntax error → 400. ``POST /sparql/update`` runs SPARQL Update (token needed).
* ``GET /queries``, ``GET /queries/{name}?var=value``: the files in ``queries/``, each query
  parameter binding the variable of that name (``dataset=MODEL`` makes the model's graphs the
  default graph, for the queries about a building graph).
* ``POST /jobs/{assemble,calibrate,diagnose,add-effect}`` → 202 and the job at once;
  ``GET /jobs/{id}`` for status, progress, result and links; ``POST /jobs/{id}/cancel``;
  ``POST /jobs/{id}/resubmit`` (:mod:`service.jobs.runner`: executors, persistence, cancellation).
* ``GET /health``.

**Auth.** Writes (uploads, jobs, cancel, SPARQL Update) need ``Authorization: Bearer <GRAPHTWIN_TOKEN>``
(without a configured token every write is refused); reads need it when ``open_reads`` is false.

**Query limits.** A query runs on a small thread pool and is abandoned after ``query_timeout_s``
(503): the response returns then, but pyoxigraph cannot interrupt a running query, which finishes
in the background and keeps its pool thread until then (queries waiting for a free thread count
against their own limit). Results above ``max_result_rows`` rows or triples are refused (422).
Updates are not time-limited: an update cannot be abandoned half way.

**Serialisation.** On the embedded store the query runs on the pyoxigraph store itself
(``store.backend.store``) so that projected variables keep their order and unbound ones their
column; a remote store answers through :meth:`~service.graph.store.SparqlBackend.query` (rows as dicts:
a variable unbound in every row has no column). Either way the rows are consumed (at most
``max_result_rows + 1``) on the query thread and written by pyoxigraph's serialisers
(``QueryResultsFormat``, ``RdfFormat``).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import re
import secrets
import tempfile
import uuid
from concurrent.futures import ThreadPoolExecutor
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated
from urllib.parse import parse_qs

import numpy as np
import pyoxigraph as ox
from fastapi import APIRouter, Depends, FastAPI, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service import __version__
from service.http.schemas import (
    AddEffectRequest, AssembleRequest, BrickReportPublic, CalibrateRequest, DiagnoseRequest, ErrorBody, Health,
    JobList, JobPublic, MeasurementsInfo, MeasurementsList, ModelInfo, ModelList, ModelUploaded, NamedQueryList,
)
from service.model.assembly import AssemblyError, IncompleteModelError, assemble
from service.report.brick import brick_report, official_brick_classes
from service.calibration.model_data import read_model_data
from service.jobs.runner import (
    JobRecord, JobRecords, JobRunner, JobStateError, add_effect_job, assemble_job, calibrate_job, diagnose_job,
    effect_version,
    job_executor,
)
from service.data.measurements import MeasurementError
from service.graph.namespaces import PREFIXES
from service.resources import queries_dir
from service.settings import Settings
from service.components.library import SignatureLibrary
from service.graph.endpoint import SparqlEndpointError
from service.graph.sparql_writes import written_graphs
from service.graph.store import EmbeddedBackend, GraphStore, ModelLoadError, drain, query_bound, rdf_format

__all__ = ["create_app", "ApiError", "MeasurementUploads", "query_form", "negotiate"]

log = logging.getLogger("graphtwin.api")


# ====================================================================== errors
class ApiError(Exception):
    """An HTTP error with an :class:`~service.http.schemas.ErrorBody`."""

    def __init__(self, status: int, detail: str, *, headers: dict[str, str] | None = None, **extra):
        super().__init__(detail)
        self.status, self.detail, self.headers, self.extra = status, detail, headers, extra


def _api_error_response(request: Request, exc: ApiError) -> JSONResponse:
    body = ErrorBody(detail=exc.detail, **exc.extra).model_dump(exclude_none=True)
    return JSONResponse(body, status_code=exc.status, headers=exc.headers)


def _validation_error_response(request: Request, exc: RequestValidationError) -> JSONResponse:
    """A request FastAPI could not validate (body, path or query) → 422 in the :class:`ErrorBody` shape,
    one problem per invalid field (the values themselves are not echoed: they may be secrets)."""
    problems = [f"{'.'.join(str(part) for part in error['loc'])}: {error['msg']}" for error in exc.errors()]
    body = ErrorBody(detail="the request is not valid: " + "; ".join(problems), problems=problems)
    return JSONResponse(body.model_dump(exclude_none=True), status_code=422)


def _store_unavailable_response(request: Request, exc: SparqlEndpointError) -> JSONResponse:
    """The external SPARQL endpoint failed or is unreachable, whichever route asked it → 503 naming it."""
    return JSONResponse(ErrorBody(detail=f"the store did not answer: {exc}").model_dump(exclude_none=True),
                        status_code=503)


def _errors(*codes: int) -> dict:
    return {code: {"model": ErrorBody} for code in codes}


# ====================================================================== service state and access
@dataclass
class Service:
    """What the routes share: ``request.app.state.graphtwin``."""

    settings: Settings
    store: GraphStore
    runner: JobRunner
    uploads: MeasurementUploads
    query_pool: ThreadPoolExecutor
    #: the official Brick ontology's classes (``GRAPHTWIN_BRICK_ONTOLOGY``), read at start-up
    brick_classes: frozenset[str] | None = None


def _service(request: Request) -> Service:
    return request.app.state.graphtwin


ServiceDep = Annotated[Service, Depends(_service)]
_bearer = HTTPBearer(auto_error=False, description="the service's GRAPHTWIN_TOKEN")
Credentials = Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]


def _check_token(service: Service, credentials: HTTPAuthorizationCredentials | None, what: str) -> None:
    expected = service.settings.token
    if expected is None:
        raise ApiError(403, f"{what} are disabled: the service was started without GRAPHTWIN_TOKEN")
    if credentials is None:
        raise ApiError(401, f"{what} need a bearer token (Authorization: Bearer …)", headers={"WWW-Authenticate": "Bearer"})
    if not secrets.compare_digest(credentials.credentials.encode("utf-8"), expected.get_secret_value().encode("utf-8")):
        raise ApiError(401, "the bearer token is not valid", headers={"WWW-Authenticate": 'Bearer error="invalid_token"'})


def require_write(service: ServiceDep, credentials: Credentials) -> None:
    """Writes always need the token."""
    _check_token(service, credentials, "writes")


def require_read(service: ServiceDep, credentials: Credentials) -> None:
    """Reads need the token unless ``open_reads``."""
    if not service.settings.open_reads:
        _check_token(service, credentials, "reads")


WriteAccess = Depends(require_write)
ReadAccess = Depends(require_read)


async def _read_body(request: Request, limit: int) -> bytes:
    """The request body, refused with 413 as soon as it exceeds ``limit`` bytes."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise ApiError(413, f"the upload has {int(declared)} bytes; the limit is {limit}")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise ApiError(413, f"the upload exceeds the limit of {limit} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


def _require_fit_models(store: GraphStore, body: CalibrateRequest | DiagnoseRequest) -> None:
    """404 unless the model to fit, and the model its fit starts from (if any), are in the store."""
    _require_model(store, body.model)
    if body.start_from is not None:
        _require_model(store, body.start_from)


def _require_model(store: GraphStore, name: str) -> str:
    try:
        GraphStore.check_name(name)
    except ValueError:
        raise ApiError(404, f"no model {name!r}") from None
    if not store.has_model(name):
        raise ApiError(404, f"no model {name!r}; known: {', '.join(store.models()) or 'none'}")
    return name


# ====================================================================== measurement uploads
_UPLOAD_ID = re.compile(r"^[0-9a-f]{16}$")


class MeasurementUploads:
    """Validated measurement CSVs: ``<root>/<model>/<id>.csv`` with ``<id>.json`` describing them."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def save(self, store: GraphStore, model_name: str, data: bytes, *, allow_gaps: bool = False) -> dict:
        """Validate ``data`` against ``model_name``'s assembled model and keep it.

        :raises MeasurementError: every problem of the file (nothing is kept then).
        :raises AssemblyError: the model does not assemble.
        """
        model = assemble(store, model_name)
        folder = self.root / model_name
        folder.mkdir(parents=True, exist_ok=True)
        upload_id = uuid.uuid4().hex[:16]
        handle, temporary = tempfile.mkstemp(dir=folder, prefix=".upload-", suffix=".csv")
        try:
            with os.fdopen(handle, "wb") as out:
                out.write(data)
            try:
                measured = read_model_data(model, temporary)
            except MeasurementError as exc:
                raise MeasurementError("the uploaded CSV", list(exc.problems)) from None
            if not allow_gaps:
                self._refuse_gaps(measured)
            info = {
                "id": upload_id, "model": model_name, "rows": measured.n_steps,
                "start": str(measured.timestamps[0]), "end": str(measured.timestamps[-1]),
                "step_s": measured.step_s, "columns": dict(measured.columns), "warnings": list(measured.warnings),
            }
            (folder / f"{upload_id}.json").write_text(json.dumps(info, indent=1), encoding="utf-8")
            os.replace(temporary, folder / f"{upload_id}.csv")
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            (folder / f"{upload_id}.json").unlink(missing_ok=True)
            raise
        return info

    @staticmethod
    def _refuse_gaps(measured) -> None:
        problems = []
        for node, series in measured.series.items():
            missing = np.flatnonzero(np.isnan(series))
            if missing.size:
                problems.append(
                    f"column {measured.columns[node]!r}: {missing.size} step(s) without a value that no short gap "
                    f"interpolation fills (first at {measured.timestamps[missing[0]]}); fill them, or upload with "
                    "allow_gaps=true to leave those steps out of the calibration"
                )
        if problems:
            raise MeasurementError("the uploaded CSV", problems)

    def list(self, model_name: str) -> list[dict]:
        folder = self.root / model_name
        if not folder.is_dir():
            return []
        return [json.loads(p.read_text(encoding="utf-8")) for p in sorted(folder.glob("*.json"))
                if (folder / f"{p.stem}.csv").is_file()]

    def delete(self, model_name: str, upload_id: str) -> None:
        """Remove upload ``upload_id`` of model ``model_name``.

        :raises KeyError: no such upload of that model.
        """
        folder = self.root / GraphStore.check_name(model_name)
        if not _UPLOAD_ID.match(upload_id or "") or not (folder / f"{upload_id}.csv").is_file():
            raise KeyError(f"no measurement upload {upload_id!r} of model {model_name}")
        (folder / f"{upload_id}.json").unlink(missing_ok=True)  # the description first: list() then skips it
        (folder / f"{upload_id}.csv").unlink()

    def locate(self, upload_id: str) -> Path:
        """The CSV of upload ``upload_id`` (under whichever model it was validated against).

        :raises KeyError: no such upload.
        """
        if _UPLOAD_ID.match(upload_id or ""):
            found = sorted(self.root.glob(f"*/{upload_id}.csv"))
            if found:
                return found[0]
        raise KeyError(f"no measurement upload {upload_id!r}")


# ====================================================================== SPARQL protocol
_PROLOGUE = re.compile(r"\s*(?:#[^\n]*(?:\n|$)|BASE\s*<[^>]*>|PREFIX\s*[^\s:<>]*:\s*<[^>]*>"  # any PN_PREFIX
                       r"|VERSION\s*(?:\"[^\"\n]*\"|'[^'\n]*'))", re.IGNORECASE)  # SPARQL 1.2's VERSION "1.2"
_KEYWORD = re.compile(r"\s*([A-Za-z]+)")
UPDATE_KEYWORDS = frozenset({"INSERT", "DELETE", "LOAD", "CLEAR", "CREATE", "DROP", "COPY", "MOVE", "ADD", "WITH"})
RESULT_TYPES = {  # in the order a wildcard gets them; plain JSON, an alias, last
    "application/sparql-results+json": ox.QueryResultsFormat.JSON,
    "application/sparql-results+xml": ox.QueryResultsFormat.XML, "text/csv": ox.QueryResultsFormat.CSV,
    "text/tab-separated-values": ox.QueryResultsFormat.TSV, "application/json": ox.QueryResultsFormat.JSON,
}
GRAPH_TYPES = {
    "text/turtle": ox.RdfFormat.TURTLE, "application/n-triples": ox.RdfFormat.N_TRIPLES,
    "application/rdf+xml": ox.RdfFormat.RDF_XML, "application/ld+json": ox.RdfFormat.JSON_LD,
}


def query_form(sparql: str) -> str | None:
    """The first keyword after the prologue (comments, BASE, PREFIX, VERSION), upper case: ``SELECT``,
    ``CONSTRUCT``, ``ASK``, ``DESCRIBE``, or an update's ``INSERT``, ``DELETE``…; None when there is none."""
    position = 0
    while (match := _PROLOGUE.match(sparql, position)) and match.end() > position:
        position = match.end()
    keyword = _KEYWORD.match(sparql, position)
    return keyword.group(1).upper() if keyword else None


_TOKEN = re.compile(
    r'"""(?:[^"\\]|\\.|"(?!""))*"""' r"|'''(?:[^'\\]|\\.|'(?!''))*'''"  # long strings
    r'|"(?:[^"\\\n]|\\.)*"' r"|'(?:[^'\\\n]|\\.)*'"  # strings
    r'|<[^<>"{}|^`\\\s]*>|#[^\n]*'  # IRIs, comments
    r"""|[^\s"'<{}()#]+|\S"""  # words (keywords, prefixed names, variables), punctuation
)


def calls_a_service(sparql: str) -> bool:
    """Whether ``sparql`` has a ``SERVICE`` clause (a federated query: the engine would fetch another
    URL), read as tokens: the word in a string, an IRI, a comment or a name does not count."""
    return fetching_keyword(sparql) == "SERVICE"


def fetching_keyword(sparql: str) -> str | None:
    """``SERVICE`` or ``LOAD`` when ``sparql`` has one (the engine would fetch another URL on the
    caller's behalf), read as tokens as :func:`calls_a_service` does; None otherwise."""
    return next((word for token in _TOKEN.findall(sparql) if (word := token.upper()) in ("SERVICE", "LOAD")), None)


def negotiate(accept: str | None, offers: list[str]) -> str | None:
    """The offered media type the ``Accept`` header prefers (RFC 9110 §12.5.1: each offer takes the
    q-value of the most specific range that matches it, ``type/subtype`` over ``type/*`` over
    ``*/*``, so ``q=0`` refuses a type a wildcard would admit); ties go to the range named first,
    then to the first offer. The first offer when the header is absent; None when it accepts none."""
    if not accept or not accept.strip():
        return offers[0]
    ranges = []  # (media range, q, position in the header)
    for index, part in enumerate(accept.split(",")):
        media, *params = [p.strip() for p in part.split(";")]
        quality = 1.0
        for param in params:
            if param.startswith("q="):
                try:
                    quality = float(param[2:])
                except ValueError:
                    quality = 0.0
        if media:
            ranges.append((media.lower(), quality, index))

    def preference(offer: str) -> tuple[float, int]:
        matching = [(2 if media == offer else 1 if media != "*/*" else 0, quality, -index)
                    for media, quality, index in ranges
                    if media in (offer, "*/*") or media.endswith("/*") and offer.startswith(media[:-1])]
        if not matching:
            return 0.0, 0
        _, quality, position = max(matching)
        return quality, position

    best = max(offers, key=lambda offer: (preference(offer), -offers.index(offer)))
    return best if preference(best)[0] > 0 else None


class _ResultTooLarge(Exception):
    pass


@dataclass(frozen=True)
class _Query:
    text: str
    form: str
    media_type: str
    default_graph: list[ox.NamedNode] | None = None
    union_default_graph: bool = False
    substitutions: dict[str, ox.NamedNode | ox.Literal] | None = None  # a named query's parameters


def _tsv_term(term) -> str:
    """A term as SPARQL TSV writes it (RDF 1.2: a triple term as ``<<( s p o )>>``; unbound: empty)."""
    if term is None:
        return ""
    if isinstance(term, ox.Triple):
        return f"<<( {_tsv_term(term.subject)} {_tsv_term(term.predicate)} {_tsv_term(term.object)} )>>"
    return str(term)


def _solutions_bytes(variables: list[str], rows: list[tuple], fmt: ox.QueryResultsFormat) -> bytes:
    """Rows of terms → ``fmt``, through pyoxigraph's TSV parser and its serialiser."""
    lines = ["\t".join(f"?{v}" for v in variables)]
    lines += ["\t".join(map(_tsv_term, row)) for row in rows]
    return ox.parse_query_results("\n".join(lines) + "\n", ox.QueryResultsFormat.TSV).serialize(format=fmt)


def _boolean_bytes(value: bool, fmt: ox.QueryResultsFormat) -> bytes:
    parsed = ox.parse_query_results(json.dumps({"head": {}, "boolean": value}), ox.QueryResultsFormat.JSON)
    return parsed.serialize(format=fmt)


def _native_answer(store: ox.Store, query: _Query, max_rows: int):
    """Run on the pyoxigraph store; the lazy result lives and dies in this call, on this thread
    (pyoxigraph results are unsendable: dropping one on another thread raises)."""
    kwargs = {"use_default_graph_as_union": True} if query.union_default_graph else (
        {"default_graph": query.default_graph} if query.default_graph else {})
    result = query_bound(store, query.text, query.substitutions, **kwargs)
    try:
        if isinstance(result, ox.QueryBoolean):
            return bool(result)
        if isinstance(result, ox.QuerySolutions):
            variables = [v.value for v in result.variables]
            return variables, drain(result, tuple, limit=max_rows + 1)
        return drain(result, limit=max_rows + 1)
    finally:
        del result  # see service.graph.store.drain


def _execute(store: GraphStore, query: _Query, max_rows: int) -> bytes:
    """Run ``query`` and serialise its answer (on a query-pool thread)."""
    backend = store.backend
    if isinstance(backend, EmbeddedBackend):
        answer = _native_answer(backend.store, query, max_rows)
    else:
        default_graph = backend.graphs() if query.union_default_graph else query.default_graph
        result = backend.query(query.text, substitutions=query.substitutions, default_graph=default_graph)
        if isinstance(result, bool):
            answer = result
        elif query.form == "SELECT":
            variables = list(dict.fromkeys(name for row in result for name in row))
            answer = (variables, [tuple(row.get(v) for v in variables) for row in result])
        else:
            answer = list(result)
    if isinstance(answer, bool):
        return _boolean_bytes(answer, RESULT_TYPES[query.media_type])
    size = len(answer[1]) if isinstance(answer, tuple) else len(answer)
    if size > max_rows:
        raise _ResultTooLarge(f"the result has more than {max_rows} rows or triples (the service's limit): "
                              "narrow the query or add a LIMIT")
    if isinstance(answer, tuple):
        return _solutions_bytes(*answer, RESULT_TYPES[query.media_type])
    fmt = GRAPH_TYPES[query.media_type]
    return ox.serialize(answer, format=fmt, prefixes=PREFIXES if fmt == ox.RdfFormat.TURTLE else None)


def _prepare(text: str | None, accept: str | None, default_graph_uris: list[str], union: bool) -> _Query:
    if not text or not text.strip():
        raise ApiError(400, "no query: give it as the query parameter or form field 'query', or as an "
                            "application/sparql-query body")
    form = query_form(text)
    if form in UPDATE_KEYWORDS:
        raise ApiError(403, "this endpoint only answers queries: send SPARQL Update to POST /sparql/update "
                            "with a bearer token")
    if calls_a_service(text):
        raise ApiError(403, "SERVICE (federated query) is refused here: the service would send requests to "
                            "other URLs on the caller's behalf; query the other endpoint directly")
    offers = list(GRAPH_TYPES) if form in ("CONSTRUCT", "DESCRIBE") else list(RESULT_TYPES)
    media = negotiate(accept, offers)
    if media is None:
        raise ApiError(406, f"cannot answer a {form or 'SPARQL'} query as {accept}; available: {', '.join(offers)}")
    try:
        graphs = [ox.NamedNode(uri) for uri in default_graph_uris] or None
    except ValueError as exc:
        raise ApiError(400, f"default-graph-uri: {exc}") from None
    return _Query(text, form or "", media, graphs, union)


async def _answer(service: Service, query: _Query) -> Response:
    settings = service.settings
    future = service.query_pool.submit(_execute, service.store, query, settings.max_result_rows)
    try:
        body = await asyncio.wait_for(asyncio.wrap_future(future), timeout=settings.query_timeout_s)
    except TimeoutError:
        raise ApiError(503, f"the query did not finish within the time limit of {settings.query_timeout_s:g} s; "
                            "it may still be running in the store (it cannot be interrupted)") from None
    except (SyntaxError, ValueError) as exc:
        raise ApiError(400, f"SPARQL syntax error: {exc}") from None
    except _ResultTooLarge as exc:
        raise ApiError(422, str(exc)) from None
    except (OSError, RuntimeError) as exc:  # an unreachable or failing SPARQL endpoint (SparqlEndpointError)
        raise ApiError(503, f"the store did not answer: {exc}") from None
    return Response(body, media_type=query.media_type)


# ====================================================================== routes: health and models
router = APIRouter(responses=_errors(422))  # every validation error has the ErrorBody shape
_RDF_BODY = {"requestBody": {"required": True, "content": {
    media: {"schema": {"type": "string"}} for media in ("text/turtle", "application/n-triples", "application/rdf+xml", "application/ld+json")
}}}
_CSV_BODY = {"requestBody": {"required": True, "content": {"text/csv": {"schema": {"type": "string"}}}}}


@router.get("/health", response_model=Health, tags=["service"], responses=_errors(503))
def health(service: ServiceDep) -> dict:
    """The service is up and its store answers."""
    try:
        service.store.backend.query("ASK {}")
    except Exception as exc:
        raise ApiError(503, f"the store does not answer: {type(exc).__name__}") from None
    backend = "embedded" if isinstance(service.store.backend, EmbeddedBackend) else "remote"
    return {"status": "ok", "backend": backend, "executor": service.settings.executor,
            "jobs_active": service.runner.active_count()}


@router.get("/models", response_model=ModelList, tags=["models"], dependencies=[ReadAccess], responses=_errors(401, 403))
def list_models(service: ServiceDep) -> dict:
    """The building models in the store."""
    names = service.store.models()
    return {"data": [{"name": n, "graph": service.store.model_graph(n).value} for n in names], "count": len(names)}


@router.get("/models/{name}", response_model=ModelInfo, tags=["models"], dependencies=[ReadAccess],
            responses=_errors(401, 403, 404))
def get_model(name: str, service: ServiceDep) -> dict:
    """A model: its graph, sizes, whether it was assembled, its measurement uploads."""
    store = service.store
    _require_model(store, name)
    return {
        "name": name, "graph": store.model_graph(name).value,
        "triples": store.backend.triple_count(store.model_graph(name)),
        "inferred_triples": store.backend.triple_count(store.inferred_graph(name)),
        "assembled": store.assembly_graph(name) in store.backend.graphs(),
        "measurements": [info["id"] for info in service.uploads.list(name)],
    }


def _load_model(store: GraphStore, name: str, data: bytes, content_type: str | None) -> dict:
    try:
        GraphStore.check_name(name)
    except ValueError as exc:
        raise ApiError(422, str(exc)) from None
    try:
        fmt = rdf_format(content_type or "text/turtle")
    except ValueError as exc:
        raise ApiError(415, str(exc)) from None
    try:
        loaded = store.load_model(name, data, fmt.media_type, source_name=f"model {name}")
    except ModelLoadError as exc:
        raise ApiError(400, str(exc), line=exc.line, column=exc.column) from None
    return {"name": name, "graph": store.model_graph(name).value, "triples": loaded.triples, "replaced": loaded.replaced,
            "changed": loaded.changed}


@router.delete("/models/{name}", status_code=204, tags=["models"], dependencies=[WriteAccess],
               responses=_errors(401, 403, 404))
def delete_model(name: str, service: ServiceDep) -> Response:
    """Remove model ``name`` with its inferences and its assembly (one transaction). Its calibration
    runs and measurement uploads stay: they describe what was done, and a model loaded again under
    the name can use the uploads."""
    _require_model(service.store, name)
    service.store.drop_model(name)
    return Response(status_code=204)


@router.get("/models/{name}/brick-report", response_model=BrickReportPublic, tags=["models"],
            dependencies=[ReadAccess], responses=_errors(401, 403, 404))
def get_brick_report(name: str, service: ServiceDep) -> dict:
    """What the Brick alignment could not use in model ``name`` (as ``graphtwin brick-report``):
    unaligned classes with what would be needed, unread relations, the assumptions made and the
    triples that would remove them, points without a column or unit. ``official_ontology`` says
    whether the service knows the official Brick classes (``GRAPHTWIN_BRICK_ONTOLOGY``)."""
    _require_model(service.store, name)
    report = brick_report(service.store, name, service.brick_classes)
    return report.to_dict() | {"official_ontology": service.brick_classes is not None}


@router.put("/models/{name}", response_model=ModelUploaded, tags=["models"], dependencies=[WriteAccess],
            openapi_extra=_RDF_BODY, responses=_errors(400, 401, 403, 413, 415, 422))
async def put_model(name: str, request: Request, response: Response, service: ServiceDep) -> dict:
    """Upload or replace building model ``name`` (its named graph; alignment runs at once).
    201 when new, 200 when replaced."""
    data = await _read_body(request, service.settings.max_upload_bytes)
    uploaded = await run_in_threadpool(_load_model, service.store, name, data, request.headers.get("content-type"))
    response.status_code = 200 if uploaded["replaced"] else 201
    return uploaded


def _save_measurements(service: Service, name: str, data: bytes, allow_gaps: bool) -> dict:
    _require_model(service.store, name)
    try:
        return service.uploads.save(service.store, name, data, allow_gaps=allow_gaps)
    except MeasurementError as exc:
        raise ApiError(422, f"the measurements do not fit model {name}", problems=list(exc.problems)) from None
    except IncompleteModelError as exc:
        raise ApiError(422, f"model {name} does not assemble", problems=list(exc.problems)) from None
    except AssemblyError as exc:
        raise ApiError(422, f"model {name} does not assemble: {exc}") from None


@router.post("/models/{name}/measurements", response_model=MeasurementsInfo, status_code=201, tags=["models"],
             dependencies=[WriteAccess], openapi_extra=_CSV_BODY, responses=_errors(401, 403, 404, 413, 422))
async def post_measurements(name: str, request: Request, service: ServiceDep,
                            allow_gaps: Annotated[bool, Query(description="accept values missing over long gaps")] = False) -> dict:
    """Upload measurements (CSV, README: data contract) for model ``name``; the id names them in jobs."""
    data = await _read_body(request, service.settings.max_upload_bytes)
    return await run_in_threadpool(_save_measurements, service, name, data, allow_gaps)


@router.get("/models/{name}/measurements", response_model=MeasurementsList, tags=["models"],
            dependencies=[ReadAccess], responses=_errors(401, 403, 404))
def list_measurements(name: str, service: ServiceDep) -> dict:
    """The measurement uploads of model ``name``."""
    _require_model(service.store, name)
    infos = service.uploads.list(name)
    return {"data": infos, "count": len(infos)}


@router.delete("/models/{name}/measurements/{upload_id}", status_code=204, tags=["models"],
               dependencies=[WriteAccess], responses=_errors(401, 403, 404))
def delete_measurements(name: str, upload_id: str, service: ServiceDep) -> Response:
    """Remove a measurement upload of model ``name`` (runs made with it keep what they recorded)."""
    try:
        service.uploads.delete(name, upload_id)
    except (KeyError, ValueError) as exc:  # no such upload, or no name a model can have
        raise ApiError(404, str(exc.args[0])) from None
    return Response(status_code=204)


# ====================================================================== routes: SPARQL
_SPARQL_ERRORS = _errors(400, 401, 403, 406, 413, 415, 422, 503)
_QUERY_BODY = {"requestBody": {"content": {
    "application/sparql-query": {"schema": {"type": "string"}},
    "application/x-www-form-urlencoded": {"schema": {"type": "object", "properties": {
        "query": {"type": "string"}, "default-graph-uri": {"type": "array", "items": {"type": "string"}}}}},
}}}


@router.get("/sparql", tags=["sparql"], dependencies=[ReadAccess], responses=_SPARQL_ERRORS)
async def sparql_get(
    request: Request, service: ServiceDep,
    query: Annotated[str | None, Query(description="the SPARQL query")] = None,
    default_graph_uri: Annotated[list[str], Query(alias="default-graph-uri")] = [],  # noqa: B006 (FastAPI reads, never mutates)
    union_default_graph: Annotated[bool, Query(alias="union-default-graph")] = False,
) -> Response:
    """SPARQL 1.1 Protocol query by GET; read-only (results by content negotiation)."""
    return await _answer(service, _prepare(query, request.headers.get("accept"), default_graph_uri, union_default_graph))


@router.post("/sparql", tags=["sparql"], dependencies=[ReadAccess], responses=_SPARQL_ERRORS,
             openapi_extra=_QUERY_BODY)
async def sparql_post(
    request: Request, service: ServiceDep,
    default_graph_uri: Annotated[list[str], Query(alias="default-graph-uri")] = [],  # noqa: B006
    union_default_graph: Annotated[bool, Query(alias="union-default-graph")] = False,
) -> Response:
    """SPARQL 1.1 Protocol query by POST (form field ``query`` or an application/sparql-query body)."""
    body = await _read_body(request, service.settings.max_upload_bytes)
    content_type = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    graphs = list(default_graph_uri)
    if content_type == "application/sparql-query":
        text = body.decode("utf-8", errors="replace")
    elif content_type == "application/x-www-form-urlencoded":
        form = parse_qs(body.decode("utf-8", errors="replace"))
        text = (form.get("query") or [None])[-1]
        graphs += form.get("default-graph-uri", [])
        union_default_graph = union_default_graph or (form.get("union-default-graph") or ["false"])[-1] == "true"
    else:
        raise ApiError(415, "send the query as application/sparql-query or as the form field 'query' "
                            "(application/x-www-form-urlencoded)")
    return await _answer(service, _prepare(text, request.headers.get("accept"), graphs, union_default_graph))


def _update(store: GraphStore, text: str) -> None:
    """Run the update, then derive again the inferences of every model whose graph it can have
    changed (:func:`~service.graph.sparql_writes.written_graphs`)."""
    try:
        store.update_models(text, written_graphs(text))
    except (SyntaxError, ValueError) as exc:
        raise ApiError(400, f"SPARQL Update syntax error: {exc}") from None
    except (RuntimeError, OSError) as exc:  # the store refused it as it ran (DROP of a graph that does not exist)
        raise ApiError(400, f"the update failed, nothing was changed: {exc}") from None


@router.post("/sparql/update", status_code=204, tags=["sparql"], dependencies=[WriteAccess],
             responses=_errors(400, 401, 403, 413, 415), openapi_extra={"requestBody": {"content": {
                 "application/sparql-update": {"schema": {"type": "string"}},
                 "application/x-www-form-urlencoded": {"schema": {"type": "object", "properties": {
                     "update": {"type": "string"}}}}}}})
async def sparql_update(request: Request, service: ServiceDep) -> Response:
    """SPARQL 1.1 Update (one transaction; a syntax error changes nothing). A model whose graph it
    changes gets its inferences derived again (the alignment rules: what the signatures match) and
    loses its assembly, as a new upload does; a model graph it drops takes them with it."""
    body = await _read_body(request, service.settings.max_upload_bytes)
    content_type = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    if content_type == "application/sparql-update":
        text = body.decode("utf-8", errors="replace")
    elif content_type == "application/x-www-form-urlencoded":
        text = (parse_qs(body.decode("utf-8", errors="replace")).get("update") or [""])[-1]
    else:
        raise ApiError(415, "send the update as application/sparql-update or as the form field 'update'")
    if not text.strip():
        raise ApiError(400, "no update given")
    if (keyword := fetching_keyword(text)) is not None:
        raise ApiError(403, f"{keyword} is refused here: the service would fetch other URLs on the caller's behalf; "
                            "load data with PUT /models/NAME")
    await run_in_threadpool(_update, service.store, text)
    return Response(status_code=204)


# ====================================================================== routes: named queries
_VARIABLE = re.compile(r"[?$]([A-Za-z_][A-Za-z0-9_]*)")


def _named_query_path(name: str) -> Path:
    path = queries_dir() / f"{name}.rq"
    if not re.fullmatch(r"[A-Za-z0-9_\-]+", name) or not path.is_file():
        known = ", ".join(sorted(p.stem for p in queries_dir().glob("*.rq")))
        raise ApiError(404, f"no query {name!r}; known: {known}")
    return path


def _describe_query(path: Path) -> dict:
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    header = []
    for line in lines:
        if not line.startswith("#"):
            break
        header.append(line.lstrip("#").strip())
    body = "\n".join(line for line in lines if not line.lstrip().startswith("#"))
    variables = list(dict.fromkeys(_VARIABLE.findall(body)))
    return {"name": path.stem, "description": " ".join(header), "variables": variables, "text": text}


def _binding(name: str, value: str):
    if value.startswith(("http://", "https://", "urn:")):
        try:
            return ox.NamedNode(value)
        except ValueError as exc:
            raise ApiError(422, f"parameter {name}: {exc}") from None
    return ox.Literal(value)


@router.get("/queries", response_model=NamedQueryList, tags=["queries"], dependencies=[ReadAccess], responses=_errors(401, 403))
def list_queries() -> dict:
    """The named queries (``queries/*.rq``) with their description and variables."""
    items = [{k: v for k, v in _describe_query(p).items() if k != "text"} for p in sorted(queries_dir().glob("*.rq"))]
    return {"data": items, "count": len(items)}


@router.get("/queries/{name}", tags=["queries"], dependencies=[ReadAccess], responses=_errors(401, 403, 404, 406, 422, 503))
async def run_named_query(
    name: str, request: Request, service: ServiceDep,
    dataset: Annotated[str | None, Query(description="model whose graphs are the default graph")] = None,
) -> Response:
    """Run ``queries/<name>.rq``; every other query parameter binds the variable of its name (an
    http(s):// or urn: value as an IRI, anything else as a string literal)."""
    described = _describe_query(_named_query_path(name))
    bindings = {}
    for key, value in request.query_params.items():
        if key == "dataset":
            continue
        if key not in described["variables"]:
            raise ApiError(422, f"query {name} has no variable {key!r}; its variables: {', '.join(described['variables'])}")
        bindings[key] = _binding(key, value)
    default_graph = None
    if dataset is not None:
        _require_model(service.store, dataset)
        default_graph = service.store.matching_dataset(dataset)
    query = _prepare(described["text"], request.headers.get("accept"), [], False)
    return await _answer(service, _Query(query.text, query.form, query.media_type, default_graph,
                                         substitutions=bindings or None))


# ====================================================================== routes: jobs
def _public(record: JobRecord) -> dict:
    data = record.to_dict()
    data["links"] = {"self": f"/jobs/{record.id}", **record.links}
    return data


def _job(service: Service, job_id: str) -> JobRecord:
    record = service.runner.get(job_id)
    if record is None:
        raise ApiError(404, f"no job {job_id!r}")
    return record


def _submit(service: Service, kind: str, params: dict, response: Response) -> dict:
    record = service.runner.submit(kind, params)
    response.headers["Location"] = f"/jobs/{record.id}"
    return _public(record)


def _require_measurements(service: Service, upload_id: str) -> None:
    try:
        service.uploads.locate(upload_id)
    except KeyError as exc:
        raise ApiError(404, str(exc.args[0])) from None


_JOB_ERRORS = _errors(401, 403, 404, 422)


@router.post("/jobs/assemble", response_model=JobPublic, status_code=202, tags=["jobs"],
             dependencies=[WriteAccess], responses=_JOB_ERRORS)
def submit_assemble(body: AssembleRequest, response: Response, service: ServiceDep) -> dict:
    """Assemble a model's simulation model and write it as triples (its assembly graph)."""
    _require_model(service.store, body.model)
    return _submit(service, "assemble", body.model_dump(), response)


@router.post("/jobs/calibrate", response_model=JobPublic, status_code=202, tags=["jobs"],
             dependencies=[WriteAccess], responses=_JOB_ERRORS)
def submit_calibrate(body: CalibrateRequest, response: Response, service: ServiceDep) -> dict:
    """Calibrate a model against a measurement upload; estimates and metrics go to a run graph."""
    _require_fit_models(service.store, body)
    _require_measurements(service, body.measurements)
    return _submit(service, "calibrate", body.model_dump(), response)


@router.post("/jobs/diagnose", response_model=JobPublic, status_code=202, tags=["jobs"],
             dependencies=[WriteAccess], responses=_JOB_ERRORS)
def submit_diagnose(body: DiagnoseRequest, response: Response, service: ServiceDep) -> dict:
    """Calibrate on train, compare on test, locate the failures and rank the missing effects."""
    _require_fit_models(service.store, body)
    _require_measurements(service, body.measurements)
    return _submit(service, "diagnose", body.model_dump(), response)


@router.post("/jobs/add-effect", response_model=JobPublic, status_code=202, tags=["jobs"],
             dependencies=[WriteAccess], responses=_errors(401, 403, 404, 409, 422))
def submit_add_effect(body: AddEffectRequest, response: Response, service: ServiceDep) -> dict:
    """Record an effect at a building node as a new model version (``version``, by default
    ``<model>+<effect>``); 409 when that version exists with other effects."""
    _require_model(service.store, body.model)
    library = SignatureLibrary.load()
    effects = sorted(s.id for s in library.values() if s.kind == "effect")
    if body.effect not in effects:
        raise ApiError(422, f"no effect {body.effect!r}; the catalog has {', '.join(effects)}")
    try:
        ox.NamedNode(body.target)
    except ValueError as exc:
        raise ApiError(422, f"target {body.target!r} is not an IRI: {exc}") from None
    try:
        effect_version(service.store, body.model_dump())
    except FileExistsError as exc:
        raise ApiError(409, str(exc)) from None
    return _submit(service, "add-effect", body.model_dump(), response)


@router.get("/jobs", response_model=JobList, tags=["jobs"], dependencies=[ReadAccess], responses=_errors(401, 403))
def list_jobs(service: ServiceDep) -> dict:
    """Every job, oldest first."""
    records = service.runner.list()
    return {"data": [_public(r) for r in records], "count": len(records)}


@router.get("/jobs/{job_id}", response_model=JobPublic, tags=["jobs"], dependencies=[ReadAccess],
            responses=_errors(401, 403, 404))
def get_job(job_id: str, service: ServiceDep) -> dict:
    """A job's status, progress messages, result and links."""
    return _public(_job(service, job_id))


@router.post("/jobs/{job_id}/cancel", response_model=JobPublic, tags=["jobs"], dependencies=[WriteAccess],
             responses=_errors(401, 403, 404, 409))
def cancel_job(job_id: str, service: ServiceDep) -> dict:
    """Cancel a queued job at once; flag a running one (its results are discarded when it stops)."""
    _job(service, job_id)
    try:
        return _public(service.runner.cancel(job_id))
    except JobStateError as exc:
        raise ApiError(409, str(exc)) from None


@router.post("/jobs/{job_id}/resubmit", response_model=JobPublic, status_code=202, tags=["jobs"],
             dependencies=[WriteAccess], responses=_errors(401, 403, 404, 409))
def resubmit_job(job_id: str, response: Response, service: ServiceDep) -> dict:
    """Run an ended job (interrupted, failed, cancelled…) again with the same parameters: a new job."""
    _job(service, job_id)
    try:
        record = service.runner.resubmit(job_id)
    except JobStateError as exc:
        raise ApiError(409, str(exc)) from None
    response.headers["Location"] = f"/jobs/{record.id}"
    return _public(record)


# ====================================================================== the app
def _open_store(settings: Settings) -> GraphStore:
    if settings.sparql_endpoint:
        token = settings.endpoint_token.get_secret_value() if settings.endpoint_token is not None else None
        return GraphStore.remote(settings.sparql_endpoint, token=token)
    return GraphStore.embedded(settings.store_path)


def create_app(settings: Settings | None = None, *, store: GraphStore | None = None) -> FastAPI:
    """The service for ``settings`` (from the environment when None).

    :param store: use this store instead of the one ``settings`` describe (tests: an in-memory one).
    Job records a stopped process left queued or running are marked ``interrupted`` here.
    """
    settings = settings or Settings()
    brick_classes = official_brick_classes(settings.brick_ontology) if settings.brick_ontology is not None else None
    store = store if store is not None else _open_store(settings)
    records = JobRecords(settings.jobs_dir)
    interrupted = records.mark_interrupted()
    if interrupted:
        log.warning("%d job(s) were interrupted by the last stop: %s", len(interrupted), ", ".join(interrupted))
    uploads = MeasurementUploads(settings.measurements_dir)
    kinds = {"assemble": assemble_job, "calibrate": calibrate_job, "diagnose": diagnose_job, "add-effect": add_effect_job}
    executor = job_executor(settings.executor, max_workers=settings.job_workers)
    runner = JobRunner(store, records, kinds, max_workers=settings.job_workers, locate_measurements=uploads.locate,
                       executor=executor)
    query_pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="graphtwin-sparql")

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        runner.shutdown(wait=True)
        query_pool.shutdown(wait=False, cancel_futures=True)

    app = FastAPI(
        title="graphtwin", version=__version__, lifespan=lifespan,
        description="Semantic HVAC models in, calibrated simulation models and missing-physics diagnoses out. "
                    "Writes need `Authorization: Bearer <token>`.",
    )
    app.state.graphtwin = Service(settings, store, runner, uploads, query_pool, brick_classes)
    app.add_exception_handler(ApiError, _api_error_response)
    app.add_exception_handler(RequestValidationError, _validation_error_response)
    app.add_exception_handler(SparqlEndpointError, _store_unavailable_response)
    app.include_router(router)
    from service.http import report_routes  # it imports this module (ApiError, ReadAccess, ServiceDep)

    app.include_router(report_routes.router)
    return app
