"""Errors over HTTP: every error body has one shape (:class:`~service.http.schemas.ErrorBody`), and
graphtwin's error hierarchy maps to statuses here, in one handler."""

from __future__ import annotations

from fastapi import Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from service.errors import (
    ConflictError,
    GraphtwinError,
    IncompleteModelError,
    InputError,
    MaintainedGraphError,
    MeasurementError,
    ModelLoadError,
    NotFoundError,
    StoreError,
    StoreRequestError,
    UnsupportedFormatError,
)
from service.http.schemas import ErrorBody

__all__ = ["ApiError", "error_responses", "EXCEPTION_HANDLERS", "status_of"]

#: Status of each kind of graphtwin error, the first class that matches in this order.
STATUSES: tuple[tuple[type[GraphtwinError], int], ...] = (
    (NotFoundError, 404), (ConflictError, 409), (MaintainedGraphError, 403), (ModelLoadError, 400),
    (UnsupportedFormatError, 415), (StoreRequestError, 400), (StoreError, 503), (InputError, 422),
    (GraphtwinError, 422),
)


class ApiError(Exception):
    """An error of the HTTP protocol itself (a missing token, a query form this endpoint refuses, a
    media type it cannot answer in), with an :class:`ErrorBody`."""

    def __init__(self, status: int, detail: str, *, headers: dict[str, str] | None = None, **extra):
        super().__init__(detail)
        self.status, self.detail, self.headers, self.extra = status, detail, headers, extra

    def response(self) -> JSONResponse:
        """This error as the response a client gets."""
        body = ErrorBody(detail=self.detail, **self.extra).model_dump(exclude_none=True)
        return JSONResponse(body, status_code=self.status, headers=self.headers)


def status_of(exc: GraphtwinError) -> int:
    return next(status for kind, status in STATUSES if isinstance(exc, kind))


def _error_body(exc: GraphtwinError) -> ErrorBody:
    """What a client reads of ``exc``: the problems listed apart where there are several, the line
    and column of a syntax error, the store's failure named as such."""
    if isinstance(exc, MeasurementError):
        first = f": {exc.problems[0]}" if exc.problems else ""
        more = f" (and {len(exc.problems) - 1} more: see problems)" if len(exc.problems) > 1 else ""
        return ErrorBody(detail=f"{exc.source}{first}{more}", problems=list(exc.problems))
    if isinstance(exc, IncompleteModelError):
        return ErrorBody(detail=exc.headline, problems=list(exc.problems), notes=list(exc.notes) or None)
    if isinstance(exc, ModelLoadError):
        return ErrorBody(detail=str(exc), line=exc.line, column=exc.column)
    if isinstance(exc, StoreError) and not isinstance(exc, StoreRequestError):
        return ErrorBody(detail=f"the store did not answer: {exc}")
    return ErrorBody(detail=str(exc))


def _graphtwin_error_response(request: Request, exc: GraphtwinError) -> JSONResponse:
    return JSONResponse(_error_body(exc).model_dump(exclude_none=True), status_code=status_of(exc))


def _api_error_response(request: Request, exc: ApiError) -> JSONResponse:
    return exc.response()


def _validation_error_response(request: Request, exc: RequestValidationError) -> JSONResponse:
    """A request FastAPI could not validate (body, path or query) → 422, one problem per invalid
    field (the values themselves are not echoed: they may be secrets)."""
    problems = [_problem(error, exc.body) for error in exc.errors()]
    body = ErrorBody(detail="the request is not valid: " + "; ".join(problems), problems=problems)
    return JSONResponse(body.model_dump(exclude_none=True), status_code=422)


def _problem(error: dict, body: object) -> str:
    """One invalid field as ``loc: message``; a body that is no JSON at all (``body``: its text, as
    FastAPI keeps it) as where its text breaks (line and column, from the character offset FastAPI
    gives) and why."""
    if error.get("type") == "json_invalid" and len(error["loc"]) == 2 and isinstance(error["loc"][1], int):
        offset, why = error["loc"][1], (error.get("ctx") or {}).get("error", "not JSON")
        text = (body if isinstance(body, str) else "")[:offset]
        return (f"the body is not valid JSON at line {text.count(chr(10)) + 1}, column {offset - text.rfind(chr(10))}: "
                f"{why}")
    return f"{'.'.join(str(part) for part in error['loc'])}: {error['msg']}"


#: What :func:`service.http.app.create_app` registers.
EXCEPTION_HANDLERS = {
    GraphtwinError: _graphtwin_error_response, ApiError: _api_error_response,
    RequestValidationError: _validation_error_response,
}


def error_responses(*codes: int) -> dict:
    """The OpenAPI ``responses`` of a route that may answer ``codes`` (each with an :class:`ErrorBody`)."""
    return {code: {"model": ErrorBody} for code in codes}
