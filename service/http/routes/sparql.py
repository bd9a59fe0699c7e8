"""``/sparql`` (SPARQL 1.1 Protocol queries, read-only), ``/sparql/update`` (SPARQL Update, token
needed; the changed models' inferences derived again) and ``/queries/{name}`` (the named queries of
``queries/``, each query parameter binding the variable of its name)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated
from urllib.parse import parse_qs

import pyoxigraph as ox
from fastapi import APIRouter, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from service.errors import GraphtwinError
from service.graph.rdf_io import sparql_syntax_message
from service.graph.sparql_writes import written_graphs
from service.graph.store import GraphStore
from service.http.deps import ReadAccess, ServiceDep, WriteAccess, require_model
from service.http.errors import ApiError, error_responses
from service.http.schemas import NamedQueryList
from service.http.sparql_protocol import SparqlQuery, answer_query, fetching_keyword, prepare_query
from service.resources import queries_dir

__all__ = ["router"]

router = APIRouter()
_SPARQL_ERRORS = error_responses(400, 401, 403, 406, 413, 415, 422, 429, 503)
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
    prepared = await run_in_threadpool(prepare_query, query, request.headers.get("accept"), default_graph_uri,
                                       union_default_graph)  # read off the event loop: /health answers meanwhile
    return await answer_query(service, prepared, request)


@router.post("/sparql", tags=["sparql"], dependencies=[ReadAccess], responses=_SPARQL_ERRORS,
             openapi_extra=_QUERY_BODY)
async def sparql_post(
    request: Request, service: ServiceDep,
    default_graph_uri: Annotated[list[str], Query(alias="default-graph-uri")] = [],  # noqa: B006
    union_default_graph: Annotated[bool, Query(alias="union-default-graph")] = False,
) -> Response:
    """SPARQL 1.1 Protocol query by POST (form field ``query`` or an application/sparql-query body)."""
    body = await request.body()  # held to the route's limit by the request gate
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
    prepared = await run_in_threadpool(prepare_query, text, request.headers.get("accept"), graphs, union_default_graph)
    return await answer_query(service, prepared, request)


def _update(store: GraphStore, text: str) -> None:
    """Refuse an update that would fetch other URLs; run the others, then derive again the
    inferences of every model whose graph it can have changed
    (:func:`~service.graph.sparql_writes.written_graphs`). On a worker thread: it reads the text."""
    if (keyword := fetching_keyword(text)) is not None:
        raise ApiError(403, f"{keyword} is refused here: the service would fetch other URLs on the caller's behalf; "
                            "load data with PUT /models/NAME")
    try:
        store.update_models(text, written_graphs(text))
    except GraphtwinError:  # a maintained graph named: 403 (nothing was changed)
        raise
    except SyntaxError as exc:
        message = sparql_syntax_message(text, exc).replace("SPARQL syntax error", "SPARQL Update syntax error", 1)
        raise ApiError(400, message) from None
    except ValueError as exc:
        raise ApiError(400, f"SPARQL Update syntax error: {exc}") from None
    except (RuntimeError, OSError) as exc:  # the store refused it as it ran (DROP of a graph that does not exist)
        raise ApiError(400, f"the update failed, nothing was changed: {exc}") from None


@router.post("/sparql/update", status_code=204, tags=["sparql"], dependencies=[WriteAccess],
             responses=error_responses(400, 401, 403, 413, 415), openapi_extra={"requestBody": {"content": {
                 "application/sparql-update": {"schema": {"type": "string"}},
                 "application/x-www-form-urlencoded": {"schema": {"type": "object", "properties": {
                     "update": {"type": "string"}}}}}}})
async def sparql_update(request: Request, service: ServiceDep) -> Response:
    """SPARQL 1.1 Update (one transaction; a syntax error changes nothing). A model whose graph it
    changes gets its inferences derived again (the alignment rules: what the signatures match) and
    loses its assembly, as a new upload does; a model graph it drops takes them with it."""
    body = await request.body()  # held to the route's limit by the request gate
    content_type = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    if content_type == "application/sparql-update":
        text = body.decode("utf-8", errors="replace")
    elif content_type == "application/x-www-form-urlencoded":
        text = (parse_qs(body.decode("utf-8", errors="replace")).get("update") or [""])[-1]
    else:
        raise ApiError(415, "send the update as application/sparql-update or as the form field 'update'")
    if not text.strip():
        raise ApiError(400, "no update given")
    await run_in_threadpool(_update, service.store, text)
    return Response(status_code=204)


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


@router.get("/queries", response_model=NamedQueryList, tags=["queries"], dependencies=[ReadAccess], responses=error_responses(401, 403))
def list_queries() -> dict:
    """The named queries (``queries/*.rq``) with their description and variables."""
    items = [{k: v for k, v in _describe_query(p).items() if k != "text"} for p in sorted(queries_dir().glob("*.rq"))]
    return {"data": items, "count": len(items)}


@router.get("/queries/{name}", tags=["queries"], dependencies=[ReadAccess], responses=error_responses(401, 403, 404, 406, 422, 429, 503))
async def run_named_query(
    name: str, request: Request, service: ServiceDep,
    dataset: Annotated[str | None, Query(description="model whose graphs are the default graph")] = None,
) -> Response:
    """Run ``queries/<name>.rq``; every other query parameter binds the variable of its name (an
    http(s):// or urn: value as an IRI, anything else as a string literal); ``model`` must name a model
    in the store or one whose runs it keeps, and binds its graphs' variables as the CLI's ``--model`` does."""
    described = _describe_query(_named_query_path(name))
    variables = described["variables"]
    bindings = {}
    for key, value in request.query_params.items():
        if key in ("dataset", "model"):
            continue
        if key not in variables:
            raise ApiError(422, f"query {name} has no variable {key!r}; its variables: {', '.join(variables)}")
        bindings[key] = _binding(key, value)
    if (model := request.query_params.get("model")) is not None:
        if not service.store.has_model(model) and not service.store.has_results(model):  # a dropped model's runs stay
            require_model(service.store, model)
        about = service.store.result_bindings(model, described["text"])
        if not set(about) & set(variables):
            raise ApiError(422, f"query {name} reads no model's results or graphs (no ?model); its variables: "
                                f"{', '.join(variables)}; give dataset=MODEL for a query about a building graph")
        bindings = {k: ox.Literal(v) if k == "model" else v for k, v in about.items() if k in variables} | bindings
    default_graph = None
    if dataset is not None:
        require_model(service.store, dataset)
        default_graph = service.store.matching_dataset(dataset)
    query = prepare_query(described["text"], request.headers.get("accept"), [], False)
    return await answer_query(service, SparqlQuery(query.text, query.form, query.media_type, default_graph,
                                                   substitutions=bindings or None), request)
