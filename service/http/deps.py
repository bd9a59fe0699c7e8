"""What the routes share: the service's state, access by bearer token, the limits on concurrent reads,
and the checks that a named model or upload exists."""

from __future__ import annotations

import hashlib
import threading
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.errors import InputError, NotFoundError
from service.graph.query_reader import QueryReader
from service.graph.store import GraphStore
from service.http.errors import ApiError
from service.http.gate import check_token
from service.http.uploads import MeasurementUploads
from service.jobs.runner import JobRunner
from service.settings import Settings
from service.workflows.requests import FitRequest

__all__ = ["ReadAdmission", "Service", "ServiceDep", "ReadAccess", "WriteAccess", "require_model", "require_fit_models"]


_RETRY_AFTER_S = "1"  # a place frees as soon as any read ends


class ReadAdmission:
    """At most ``total`` reads at once (the query workers and a short queue) and ``per_client`` of
    one client: by its address, and by its bearer token when it gives one. A read over either limit
    is refused at once (429 with ``Retry-After``) rather than queued behind the others."""

    def __init__(self, total: int, per_client: int) -> None:
        self.total, self.per_client = total, per_client
        self._lock = threading.Lock()
        self._running = 0
        self._by_client: Counter[str] = Counter()

    @staticmethod
    def clients(request: Request) -> list[str]:
        """The keys ``request`` counts against: its address, and a digest of its token when it gives one."""
        keys = [f"address {request.client.host if request.client else 'unknown'}"]
        scheme, _, token = (request.headers.get("authorization") or "").partition(" ")
        if scheme.lower() == "bearer" and token.strip():
            keys.append("token " + hashlib.sha256(token.strip().encode()).hexdigest())
        return keys

    @contextmanager
    def admitted(self, clients: list[str]) -> Iterator[None]:
        """Hold a place for one read of ``clients`` while it runs.

        :raises ApiError: 429 when the service or one of ``clients`` is at its limit."""
        with self._lock:
            if self._running >= self.total:
                raise ApiError(429, f"the service runs {self.total} SPARQL reads already (its limit): retry shortly",
                               headers={"Retry-After": _RETRY_AFTER_S})
            if any(self._by_client[key] >= self.per_client for key in clients):
                raise ApiError(429, f"at most {self.per_client} SPARQL reads of one client at once: wait for "
                                    "your others to end", headers={"Retry-After": _RETRY_AFTER_S})
            self._running += 1
            self._by_client.update(clients)
        try:
            yield
        finally:
            with self._lock:
                self._running -= 1
                self._by_client.subtract(clients)
                for key in clients:
                    if self._by_client[key] <= 0:
                        del self._by_client[key]


@dataclass
class Service:
    """What the routes share: ``request.app.state.graphtwin``."""

    settings: Settings
    store: GraphStore
    runner: JobRunner
    uploads: MeasurementUploads
    reads: QueryReader
    read_admission: ReadAdmission
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
