"""What the routes share: the service's state, access by bearer token, and the checks that a named
model or upload exists."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.errors import InputError, NotFoundError
from service.graph.store import GraphStore
from service.http.gate import check_token
from service.http.uploads import MeasurementUploads
from service.jobs.runner import JobRunner
from service.settings import Settings
from service.workflows.requests import FitRequest

__all__ = ["Service", "ServiceDep", "ReadAccess", "WriteAccess", "require_model", "require_fit_models"]


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


def require_write(service: ServiceDep, credentials: Credentials) -> None:
    """Writes always need the token (checked before the body by :class:`~service.http.gate.RequestGate`
    too; here it documents the route's security in the OpenAPI document)."""
    check_token(service.settings, credentials.credentials if credentials else None, "writes")


def require_read(service: ServiceDep, credentials: Credentials) -> None:
    """Reads need the token unless ``open_reads``."""
    if not service.settings.open_reads:
        check_token(service.settings, credentials.credentials if credentials else None, "reads")


WriteAccess = Depends(require_write)
ReadAccess = Depends(require_read)


def require_model(store: GraphStore, name: str) -> str:
    """``name`` when the store holds that model.

    :raises NotFoundError: naming the models it holds.
    """
    try:
        GraphStore.check_name(name)
    except InputError:
        raise NotFoundError(f"no model {name!r}") from None
    if not store.has_model(name):
        raise NotFoundError(f"no model {name!r}; known: {', '.join(store.models()) or 'none'}")
    return name


def require_fit_models(service: Service, request: FitRequest) -> Path:
    """The model to fit, the model its fit starts from (if any) and its measurement upload exist;
    the upload's CSV.

    :raises NotFoundError: one of them does not.
    """
    require_model(service.store, request.model)
    if request.start_from is not None:
        require_model(service.store, request.start_from)
    return service.uploads.locate(request.measurements)
