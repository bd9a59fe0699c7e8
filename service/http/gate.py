"""What every request passes before its body is read: a write's bearer token, and the body's size
held to its route's limit (413 as soon as it exceeds it, declared or streamed). FastAPI parses a
JSON body before a route's dependencies run, so a route's own check would come after the parsing."""

from __future__ import annotations

import secrets

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.http.errors import ApiError
from service.settings import Settings

__all__ = ["RequestGate", "check_token"]

_READS = {"GET", "HEAD", "OPTIONS"}


def check_token(settings: Settings, token: str | None, what: str) -> None:
    """``token`` (a bearer token, None when none was sent) may do ``what`` ("writes", "reads").

    :raises ApiError: 403 when the service has no token (every write refused), 401 otherwise.
    """
    expected = settings.token
    if expected is None:
        raise ApiError(403, f"{what} are disabled: the service was started without GRAPHTWIN_TOKEN")
    if token is None:
        raise ApiError(401, f"{what} need a bearer token (Authorization: Bearer …)", headers={"WWW-Authenticate": "Bearer"})
    if not secrets.compare_digest(token.encode("utf-8"), expected.get_secret_value().encode("utf-8")):
        raise ApiError(401, "the bearer token is not valid", headers={"WWW-Authenticate": 'Bearer error="invalid_token"'})


def _bearer(headers: Headers) -> str | None:
    scheme, _, token = (headers.get("authorization") or "").partition(" ")
    return token.strip() or None if scheme.lower() == "bearer" else None


def _writes(method: str, path: str) -> bool:
    """Whether the request changes something (``POST /sparql`` is a query sent by POST)."""
    return method not in _READS and path.rstrip("/") != "/sparql"


def _limit(settings: Settings, method: str, path: str) -> int:
    """The largest body the route takes: uploads (models, measurements, SPARQL Update), queries, the rest."""
    parts = path.strip("/").split("/")
    if (method == "PUT" and parts[0] == "models" and len(parts) == 2) or parts[-1] == "measurements" or \
            parts == ["sparql", "update"]:
        return settings.max_upload_bytes
    if parts == ["sparql"]:
        return settings.max_query_bytes
    return settings.max_request_bytes


class RequestGate:
    """ASGI middleware: refuses a write without its token, and a body over its route's limit, before
    the body is read."""

    def __init__(self, app: ASGIApp, settings: Settings):
        self.app, self.settings = app, settings

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        method, path, headers = scope["method"], scope["path"], Headers(scope=scope)
        limit = _limit(self.settings, method, path)
        try:
            if _writes(method, path):
                check_token(self.settings, _bearer(headers), "writes")
            declared = headers.get("content-length")
            if declared is not None and declared.isdigit() and int(declared) > limit:
                raise ApiError(413, f"the request body has {int(declared)} bytes; the limit here is {limit}")
        except ApiError as refused:
            await refused.response()(scope, receive, send)
            return
        received = 0

        async def limited() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise ApiError(413, f"the request body exceeds the limit here of {limit} bytes")
            return message

        await self.app(scope, limited, send)
