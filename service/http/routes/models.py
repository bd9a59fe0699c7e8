"""``/health``, ``/models/{name}`` (upload, read, delete, Brick report) and its measurement uploads."""

from __future__ import annotations

from typing import Annotated

import pyoxigraph as ox
from fastapi import APIRouter, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from service.errors import ConflictError, GraphtwinError, IncompleteModelError, InputError, UnsupportedFormatError
from service.graph.backend import EmbeddedBackend
from service.graph.rdf_io import rdf_format
from service.graph.store import GraphStore
from service.graph.vocabulary import with_term_locations
from service.http.deps import ReadAccess, Service, ServiceDep, WriteAccess, require_model
from service.http.errors import ApiError, error_responses
from service.http.schemas import (
    BrickReportPublic,
    Health,
    MeasurementsInfo,
    MeasurementsList,
    ModelInfo,
    ModelList,
    ModelUploaded,
)
from service.model.assembly import assemble
from service.report.brick import brick_report

__all__ = ["router"]

router = APIRouter()
_RDF_BODY = {"requestBody": {"required": True, "content": {
    media: {"schema": {"type": "string"}} for media in ("text/turtle", "application/n-triples", "application/rdf+xml", "application/ld+json")
}}}
_CSV_BODY = {"requestBody": {"required": True, "content": {"text/csv": {"schema": {"type": "string"}}}}}


@router.get("/health", response_model=Health, tags=["service"], responses=error_responses(503))
def health(service: ServiceDep) -> dict:
    """The service is up and its store answers."""
    try:
        service.store.backend.query("ASK {}")
    except Exception as exc:
        raise ApiError(503, f"the store does not answer: {type(exc).__name__}") from None
    backend = "embedded" if isinstance(service.store.backend, EmbeddedBackend) else "remote"
    return {"status": "ok", "backend": backend, "executor": service.settings.executor,
            "jobs_active": service.runner.active_count()}


@router.get("/models", response_model=ModelList, tags=["models"], dependencies=[ReadAccess],
            responses=error_responses(401, 403))
def list_models(service: ServiceDep) -> dict:
    """The building models in the store."""
    names = service.store.models()
    return {"data": [{"name": n, "graph": service.store.model_graph(n).value} for n in names], "count": len(names)}


@router.get("/models/{name}", response_model=ModelInfo, tags=["models"], dependencies=[ReadAccess],
            responses=error_responses(401, 403, 404))
def get_model(name: str, service: ServiceDep) -> dict:
    """A model: its graph, sizes, whether it was assembled, its measurement uploads."""
    store = service.store
    require_model(store, name)
    return {
        "name": name, "graph": store.model_graph(name).value,
        "triples": store.backend.triple_count(store.model_graph(name)),
        "inferred_triples": store.backend.triple_count(store.inferred_graph(name)),
        "assembled": store.assembly_graph(name) in store.backend.graphs(),
        "measurements": [info["id"] for info in service.uploads.list(name)],
    }


def _load_model(store: GraphStore, name: str, data: bytes, content_type: str | None) -> dict:
    GraphStore.check_name(name)  # before the format: a bad name is a 422 whatever the media type
    # absent, or curl's default for --data-binary (form-urlencoded, which no model is): Turtle
    form = (content_type or "").split(";")[0].strip().lower() == "application/x-www-form-urlencoded"
    fmt = rdf_format("text/turtle" if form or not content_type else content_type)
    loaded = store.load_model(name, data, fmt.media_type, source_name=f"model {name}")
    return {"name": name, "graph": store.model_graph(name).value, "triples": loaded.triples, "replaced": loaded.replaced,
            "changed": loaded.changed,
            "assembly": _assembly_check(store, name, data.decode("utf-8", errors="replace"))}


def _assembly_check(store: GraphStore, name: str, text: str) -> dict:
    """Assemble model ``name`` without writing: complete or not, why not, and its notes (an upload is
    stored either way; the answer says what the model is worth before any data are sent); a misspelt
    term's sentence says where the uploaded ``text`` first uses it."""
    try:
        model = assemble(store, name)
    except IncompleteModelError as exc:
        return {"complete": False, "problems": with_term_locations(exc.problems, text, f"model {name}"),
                "notes": with_term_locations(exc.notes, text, f"model {name}")}
    except GraphtwinError as exc:
        return {"complete": False, "problems": [str(exc)], "notes": []}
    except Exception as exc:  # noqa: BLE001 (the upload is stored: say the assembly failed, not a 500)
        return {"complete": False, "problems": [f"the assembly failed: {type(exc).__name__}: {exc}"], "notes": []}
    return {"complete": True, "problems": [], "notes": with_term_locations(model.notes, text, f"model {name}")}


@router.delete("/models/{name}", status_code=204, tags=["models"], dependencies=[WriteAccess],
               responses=error_responses(401, 403, 404))
def delete_model(name: str, service: ServiceDep) -> Response:
    """Remove model ``name`` with its inferences and its assembly (one transaction). Its calibration
    runs and measurement uploads stay: they describe what was done, and a model loaded again under
    the name can use the uploads."""
    require_model(service.store, name)
    service.store.drop_model(name)
    return Response(status_code=204)


@router.get("/models/{name}/brick-report", response_model=BrickReportPublic, tags=["models"],
            dependencies=[ReadAccess], responses=error_responses(401, 403, 404))
def get_brick_report(name: str, service: ServiceDep) -> dict:
    """What the Brick alignment could not use in model ``name`` (as ``graphtwin brick-report``).
    ``official_ontology`` says whether the service knows the official Brick classes
    (``GRAPHTWIN_BRICK_ONTOLOGY``)."""
    require_model(service.store, name)
    report = brick_report(service.store, name, service.brick_classes)
    return report.to_dict() | {"official_ontology": service.brick_classes is not None}


@router.put("/models/{name}", response_model=ModelUploaded, tags=["models"], dependencies=[WriteAccess],
            openapi_extra=_RDF_BODY, responses=error_responses(400, 401, 403, 413, 415, 422))
async def put_model(name: str, request: Request, response: Response, service: ServiceDep) -> dict:
    """Upload or replace building model ``name`` (its named graph; alignment runs at once), and say
    what assembling it finds (``assembly``: complete or not, why not, its notes; nothing written).
    201 when new, 200 when replaced."""
    data = await request.body()  # held to the route's limit by the request gate
    uploaded = await run_in_threadpool(_load_model, service.store, name, data, request.headers.get("content-type"))
    response.status_code = 200 if uploaded["replaced"] else 201
    return uploaded


def _save_measurements(service: Service, name: str, data: bytes, allow_gaps: bool) -> dict:
    require_model(service.store, name)
    return service.uploads.save(service.store, name, data, allow_gaps=allow_gaps)


@router.post("/models/{name}/measurements", response_model=MeasurementsInfo, status_code=201, tags=["models"],
             dependencies=[WriteAccess], openapi_extra=_CSV_BODY,
             responses=error_responses(401, 403, 404, 413, 415, 422))
async def post_measurements(name: str, request: Request, response: Response, service: ServiceDep,
                            allow_gaps: Annotated[bool, Query(description="accept values missing over long gaps")] = False) -> dict:
    """Upload measurements (CSV, docs/data.md: the data contract) for model ``name``; the id names
    them in jobs. The same file uploaded again keeps its id (200, ``"new": false``)."""
    if request.headers.get("content-type", "").split(";")[0].strip().lower().startswith("multipart/"):
        raise UnsupportedFormatError(
            "measurements are the CSV itself as the request body (curl --data-binary @data.csv -H 'Content-Type: "
            "text/csv'), not a multipart form (curl -F)")
    data = await request.body()  # held to the route's limit by the request gate
    saved = await run_in_threadpool(_save_measurements, service, name, data, allow_gaps)
    response.status_code = 201 if saved["new"] else 200
    return saved


@router.get("/models/{name}/measurements", response_model=MeasurementsList, tags=["models"],
            dependencies=[ReadAccess], responses=error_responses(401, 403, 404))
def list_measurements(name: str, service: ServiceDep) -> dict:
    """The measurement uploads of model ``name``, also of a model deleted since (its uploads stay)."""
    try:
        infos = service.uploads.list(GraphStore.check_name(name))
    except InputError:  # no name a model can have
        infos = []
    if not infos:
        require_model(service.store, name)
    return {"data": infos, "count": len(infos)}


@router.delete("/models/{name}/measurements/{upload_id}", status_code=204, tags=["models"],
               dependencies=[WriteAccess], responses=error_responses(401, 403, 404, 409))
def delete_measurements(name: str, upload_id: str, service: ServiceDep, force: Annotated[bool, Query(
        description="remove it though stored runs read it (their report pages then lose their plots)")] = False,
) -> Response:
    """Remove a measurement upload of model ``name``; 409 naming the stored runs made with it unless
    ``force`` (they keep what they recorded, but their report pages plot the upload)."""
    service.uploads.require(name, upload_id)  # no such upload: 404 before anything is looked up
    runs = [] if force else [row["run"].value for row in service.store.run_named_query(
        "run-data-sources", source=ox.Literal(f"{upload_id}.csv"))]
    if runs:
        named = ", ".join(r.rsplit("/", 1)[-1] for r in runs[:5]) + (" …" if len(runs) > 5 else "")
        raise ConflictError(f"upload {upload_id} is the data of {len(runs)} stored run(s), whose report pages plot "
                            f"it: {named}; "
                            "delete with force=true to remove it anyway")
    service.uploads.delete(name, upload_id)
    return Response(status_code=204)
