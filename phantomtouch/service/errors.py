"""Every refusal of the service, mapped to HTTP status, error code and WebSocket close code.

The exception tree the server adds below the package root::

    PhantomTouchError                    phantomtouch.errors
    ├── ParameterError                   422 invalid
    │   └── FieldError                   422 invalid     (fields: the path it names, or body)
    ├── EngineBusyError                  503 busy
    ├── DeviceError                      503 device
    ├── ProtocolError                    422 invalid
    └── ServiceError                     (this module)
        ├── NotFoundError                404 not_found
        ├── MissingReferenceError        422 invalid     (a body field names what is not held)
        ├── TooLargeError                413 too_large   (WebSocket: close 1009)
        ├── RateLimitedError             429 rate_limited (WebSocket: close 1008 if sustained)
        ├── QuotaError                   429 quota       (one client's fair share is used up)
        ├── StorageError                 503 storage     (the pattern store is full or damaged)
        ├── UnauthorizedError            401 unauthorized (WebSocket: close 1008)
        ├── ForbiddenOriginError         403 forbidden_origin (WebSocket: handshake refused)
        ├── UnknownHostError             421 unknown_host (WebSocket: handshake refused)
        ├── UnsupportedMediaTypeError    415 unsupported_media_type
        └── StoredPatternError           500 stored_pattern (the library's row, not the request)

A client that leaves before its request body has arrived is no error of the service:
it is counted with status 499 and nothing is logged.

pydantic's ``ValidationError`` and FastAPI's ``RequestValidationError`` are 422 ``invalid``
with one ``fields`` entry per problem, at most :data:`MAX_FIELDS` of them (the message says
how many more there were). :func:`install` registers the handlers; the
WebSocket session asks :func:`describe` for the same code and message.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field, ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect
from starlette.routing import Match

from phantomtouch.errors import (
    DeviceError,
    EngineBusyError,
    FieldError,
    ParameterError,
    PhantomTouchError,
    ProtocolError,
)
from phantomtouch.schema.validation import error_item, merge_branches, problem_line

ErrorCode = Literal[
    "invalid",
    "unauthorized",
    "forbidden_origin",
    "forbidden",
    "unknown_host",
    "unsupported_media_type",
    "stored_pattern",
    "not_found",
    "method_not_allowed",
    "too_large",
    "rate_limited",
    "quota",
    "busy",
    "storage",
    "device",
    "invalid_json",
    "unknown_type",
]

WS_CLOSE_UNSUPPORTED_DATA = 1003
"""A binary frame: the protocol is JSON text."""
WS_CLOSE_POLICY_VIOLATION = 1008
"""Missing or wrong token, a refused handshake where the server cannot answer it with an
HTTP status, or the message rate limit exceeded for a second on end."""
WS_CLOSE_MESSAGE_TOO_BIG = 1009
"""A message over ``max_ws_message_bytes``."""
WS_CLOSE_TRY_AGAIN_LATER = 1013
"""The connection's slot was given to a newcomer (``max_ws_connections`` in all, or
``max_ws_connections_per_address`` from the address, were open: it held nothing, or was
silent longest), or every slot is held by loopback connections, which never yield."""


_RETRY_SOON: Mapping[str, str] = {"Retry-After": "1"}


class ServiceError(PhantomTouchError):
    """A request the service refuses for a reason of its own (not of the renderer).

    Each kind of refusal is a subclass that states its HTTP status, error code and extra
    response headers in its class line: ``class X(ServiceError, status_code=404,
    code="not_found")``; what it leaves out it inherits.
    """

    status_code = 400
    code: ErrorCode = "invalid"
    headers: ClassVar[Mapping[str, str]] = {}

    def __init_subclass__(
        cls,
        *,
        status_code: int | None = None,
        code: ErrorCode | None = None,
        headers: Mapping[str, str] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init_subclass__(**kwargs)
        if status_code is not None:
            cls.status_code = status_code
        if code is not None:
            cls.code = code
        if headers is not None:
            cls.headers = headers

    def __init__(self, message: str, *, field: str | None = None, value: Any = None) -> None:
        super().__init__(message)
        self.field = field
        self.value = value


class NotFoundError(ServiceError, LookupError, status_code=404, code="not_found"):
    """An unknown job, pattern, preset or route."""


class MissingReferenceError(ServiceError, status_code=422):
    """A body field names something the service does not hold (a pattern's clip that is
    not in the library): the body is at fault, 422 naming the field."""


class TooLargeError(ServiceError, status_code=413, code="too_large"):
    """A request body or WebSocket message over its size limit."""


class RateLimitedError(ServiceError, status_code=429, code="rate_limited", headers=_RETRY_SOON):
    """Too many requests or messages; retry after a moment."""


class SourcesFullError(ServiceError, status_code=503, code="busy", headers=_RETRY_SOON):
    """An input's connection slots are full and no source may yield one to a newcomer
    (:mod:`phantomtouch.service.admission`); a WebSocket is closed 1013."""


class QuotaError(ServiceError, status_code=429, code="quota", headers=_RETRY_SOON):
    """One client's share (contacts, voices, voice-seconds ahead) is used up; others go on."""


class StorageError(ServiceError, status_code=503, code="storage"):
    """The pattern store cannot be read or written: its disk is full or its file damaged."""


class UnauthorizedError(
    ServiceError, status_code=401, code="unauthorized", headers={"WWW-Authenticate": "Bearer"}
):
    """A token is required and was missing or wrong."""


class ForbiddenOriginError(ServiceError, status_code=403, code="forbidden_origin"):
    """A browser request or WebSocket handshake from a web page of another origin."""


class UnknownHostError(ServiceError, status_code=421, code="unknown_host"):
    """A ``Host`` the service does not answer to (DNS rebinding, a misdirected request)."""


class UnsupportedMediaTypeError(ServiceError, status_code=415, code="unsupported_media_type"):
    """A request body not declared as ``application/json``."""


class StoredPatternError(ServiceError, status_code=500, code="stored_pattern"):
    """A row of the pattern library that no longer reads as a pattern: the server's fault."""


class FieldProblem(BaseModel):
    """One refused field: where, what was sent, and why."""

    field: str = Field(description="Dotted path of the field, e.g. `path.points_cm[0]`.")
    value: Any = Field(default=None, description="The value sent (shortened when long).")
    message: str = Field(description="Why it was refused, with the allowed range.")


class ErrorDetail(BaseModel):
    code: ErrorCode
    message: str = Field(description="Names the field, the value and what is allowed.")
    fields: list[FieldProblem] = Field(default_factory=list)


class ErrorBody(BaseModel):
    """The body of every refused request."""

    error: ErrorDetail

    model_config = {
        "json_schema_extra": {
            "examples": [
                {
                    "error": {
                        "code": "invalid",
                        "message": "speed_cm_s=0: Input should be greater than 0",
                        "fields": [
                            {
                                "field": "speed_cm_s",
                                "value": 0,
                                "message": "Input should be greater than 0",
                            }
                        ],
                    }
                }
            ]
        }
    }


@dataclass(frozen=True)
class Problem:
    """An exception described for the wire: HTTP status, code, message and fields."""

    status_code: int
    code: ErrorCode
    message: str
    fields: list[dict[str, Any]] = field(default_factory=list)
    headers: Mapping[str, str] = field(default_factory=dict)

    def body(self) -> dict[str, Any]:
        return {"error": {"code": self.code, "message": self.message, "fields": self.fields}}


MAX_FIELDS = 20
"""Most ``fields`` entries in one answer; the message counts the rest."""
_MAX_VALUE_CHARS = 120
_LOCATION_PREFIXES = {"body", "query", "path", "header", "cookie"}
_UNION_TAGS = {"touch", "preset", "named"}


def _short_value(value: Any) -> Any:
    """The value as sent if it is small JSON, else a shortened text of it."""
    try:
        text = json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        text = repr(value)
        return text if len(text) <= _MAX_VALUE_CHARS else text[: _MAX_VALUE_CHARS - 3] + "..."
    if len(text) <= _MAX_VALUE_CHARS:
        return value
    return text[: _MAX_VALUE_CHARS - 3] + "..."


def _location(loc: Sequence[int | str], *, tags: set[str]) -> str:
    items = list(loc)
    if items and items[0] in _LOCATION_PREFIXES:
        items = items[1:]
    if len(items) > 1 and items[0] in tags:
        items = items[1:]
    parts: list[str] = []
    for item in items:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        else:
            parts.append(("." if parts else "") + str(item))
    return "".join(parts) or "body"


def field_problems(errors: Sequence[Any], *, tags: set[str] = _UNION_TAGS) -> list[dict[str, Any]]:
    """pydantic error dicts as ``[{field, value, message}]`` (union tags and ``body`` dropped).

    Only the first :data:`MAX_FIELDS` errors are described.
    """
    problems = []
    for err in errors[:MAX_FIELDS]:
        missing = err.get("type") == "missing"
        item = error_item(err, prefixes=_LOCATION_PREFIXES, tags=tags)
        problems.append(
            {
                "field": item["field"] or _location(err.get("loc", ()), tags=tags),
                "value": None if missing else _short_value(item["value"]),
                "message": item["message"],
            }
        )
    return merge_branches(problems)


def _summary(problems: list[dict[str, Any]], total: int) -> str:
    parts = []
    for item in problems[:MAX_FIELDS]:
        if item["value"] is None and item["message"] == "Field required":
            parts.append(f"{item['field']}: field required")
        else:
            parts.append(problem_line(item["field"], json.dumps(item["value"]), item["message"]))
    more = total - len(parts)
    if more > 0:
        parts.append(f"and {more} more problems ({total} in all; the first {len(parts)} listed)")
    return "; ".join(parts) or "invalid request"


def invalid(problems: list[dict[str, Any]], *, total: int | None = None) -> Problem:
    """A 422 ``invalid`` problem from field problems (``total``: all problems found)."""
    shown = problems[:MAX_FIELDS]
    return Problem(422, "invalid", _summary(shown, total or len(problems)), shown)


def validation_problem(exc: ValidationError | RequestValidationError) -> Problem:
    """A validation error as a 422 ``invalid`` problem with at most :data:`MAX_FIELDS` fields."""
    errors = exc.errors(include_url=False) if isinstance(exc, ValidationError) else exc.errors()
    problems = field_problems(errors)
    merged = min(len(errors), MAX_FIELDS) - len(problems)  # a union's branches, as one
    return invalid(problems, total=len(errors) - merged)


def _problem(field: str, value: Any, message: str) -> dict[str, Any]:
    return {"field": field, "value": _short_value(value), "message": message}


_NAMED = re.compile(r"([a-z_][a-z0-9_]*(?:\.[a-z_][a-z0-9_]*|\[\d+\])*):")
"""A message's head that names a field without its value: ``path.keyframes[2]:``."""


def _field_and_value(message: str) -> tuple[str, Any]:
    """The field and value a renderer message starts with (``"name=value: why"``).

    The value is read back as JSON (numbers, ``true``) or as a quoted string (``'x'``);
    one that is neither (a tuple, a long text) is None, as it is for ``"name: why"``.
    """
    head = message.split(" ", 1)[0]
    if "=" not in head:
        named = _NAMED.fullmatch(head)
        return (named.group(1), None) if named else ("body", None)
    field, _, text = head.partition("=")
    text = text.rstrip(":;,")
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return field, text[1:-1]
    try:
        value = json.loads(text)
    except ValueError:
        return field, None
    return field, value if isinstance(value, int | float | bool) else None


def describe(exc: BaseException) -> Problem:
    """The one mapping from an exception to its status, code, message and fields."""
    if isinstance(exc, RequestValidationError | ValidationError):
        return validation_problem(exc)
    if isinstance(exc, ServiceError):
        message = str(exc)
        fields = [] if exc.field is None else [_problem(exc.field, exc.value, message)]
        return Problem(exc.status_code, exc.code, message, fields, exc.headers)
    if isinstance(exc, EngineBusyError):
        return Problem(503, "busy", str(exc) or "the engine is busy", headers=_RETRY_SOON)
    if isinstance(exc, DeviceError):
        return Problem(503, "device", str(exc))
    if isinstance(exc, FieldError):
        message = str(exc)
        return Problem(422, "invalid", message, [_problem(exc.field or "body", exc.value, message)])
    if isinstance(exc, ParameterError | ProtocolError | PhantomTouchError):
        message = str(exc)
        field, value = _field_and_value(message)
        return Problem(422, "invalid", message, [_problem(field, value, message)])
    raise TypeError(f"no mapping for {type(exc).__name__}") from exc


def problem_response(problem: Problem) -> JSONResponse:
    return JSONResponse(problem.body(), status_code=problem.status_code, headers=problem.headers)


_METHODS = ("DELETE", "GET", "HEAD", "PATCH", "POST", "PUT")


def _allowed_methods(request: Request) -> str:
    """The methods some route of the app answers on the request's path (for ``Allow``)."""
    allowed = []
    for method in _METHODS:
        scope = {**request.scope, "method": method}
        if any(route.matches(scope)[0] is Match.FULL for route in request.app.router.routes):
            allowed.append(method)
    return ", ".join(allowed)


async def _http_exception(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    headers = dict(exc.headers or {})
    if exc.status_code == 404:
        message = f"no route {request.url.path!r}; see /openapi.json"
        return problem_response(
            Problem(404, "not_found", message, [_problem("path", request.url.path, message)])
        )
    if exc.status_code == 405:
        allow = _allowed_methods(request)
        headers["Allow"] = allow
        message = f"method {request.method} not allowed on {request.url.path!r}; allowed: {allow}"
        fields = [_problem("method", request.method, message)]
        return problem_response(Problem(405, "method_not_allowed", message, fields, headers))
    problem = describe(TooLargeError(exc.detail, field="body")) if exc.status_code == 413 else None
    if problem is None:
        message = str(exc.detail)
        if exc.status_code == 400:
            message = f"the body is not JSON in UTF-8: {message}"
        status = 422 if exc.status_code == 400 else exc.status_code
        problem = Problem(status, "invalid", message, [_problem("body", None, message)], headers)
    return problem_response(problem)


async def _described(request: Request, exc: Exception) -> JSONResponse:
    return problem_response(describe(exc))


CLIENT_CLOSED_REQUEST = 499
"""Status counted for a request whose client left before its body arrived (no one reads
the answer; the status nginx uses for the same case)."""


async def _client_gone(request: Request, exc: Exception) -> Response:
    return Response(status_code=CLIENT_CLOSED_REQUEST)


def install(app: FastAPI) -> None:
    """Register the handlers: every refusal leaves the service as an :class:`ErrorBody`."""
    app.add_exception_handler(RequestValidationError, _described)
    app.add_exception_handler(ValidationError, _described)
    app.add_exception_handler(PhantomTouchError, _described)
    app.add_exception_handler(StarletteHTTPException, _http_exception)
    app.add_exception_handler(ClientDisconnect, _client_gone)


def _response(description: str) -> dict[str, Any]:
    return {"model": ErrorBody, "description": description}


RESPONSES: dict[int | str, dict[str, Any]] = {
    401: _response("A token is required and was missing or wrong (`unauthorized`)."),
    404: _response("Unknown job, pattern or preset (`not_found`)."),
    413: _response("Request body over the size limit (`too_large`)."),
    415: _response("A request body not sent as `application/json` (`unsupported_media_type`)."),
    422: _response("A field is out of range or malformed (`invalid`); `fields` name each."),
    429: _response(
        "Too many requests at once (`rate_limited`), or this client's share of the voices "
        "is used up (`quota`, the message names which); retry after `Retry-After`."
    ),
    500: _response("A stored pattern no longer reads as a pattern (`stored_pattern`)."),
    503: _response(
        "The engine is full and its voice policy refuses (`busy`), the engine is restarting "
        "or the sound card failed (`device`), or the pattern store is full or damaged "
        "(`storage`)."
    ),
}
"""Documented error responses, picked per route with :func:`responses`."""


def responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """The documented error responses of one route."""
    return {status: RESPONSES[status] for status in statuses}
