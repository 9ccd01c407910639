"""The exceptions this client raises.

::

    ClientError                               every error this client raises
    ├── ParameterError(ValueError)            an argument is out of range (checked locally)
    ├── TransportError                        the server could not be reached or answered garbage
    │   └── ConnectionLost                    the WebSocket closed while a reply was awaited
    ├── ReplyTimeout(TimeoutError)            no reply in time
    └── ApiError                              the server refused a request (REST or WebSocket)
        ├── InvalidRequest(ParameterError)    code "invalid": a field is out of range
        ├── MalformedMessage                  code "invalid_json" or "unknown_type"
        ├── Unauthorized                      code "unauthorized": token missing or wrong
        ├── NotFound                          code "not_found": unknown job, pattern, preset
        ├── TooLarge                          code "too_large"
        ├── RateLimited                       code "rate_limited"
        │   └── QuotaExceeded                 code "quota": this client's fair share is used
        ├── MethodNotAllowed                  code "method_not_allowed"
        ├── Busy                              code "busy": the engine is full
        ├── DeviceFailed                      code "device": the sound card failed, or the
        │                                     engine is restarting
        └── StorageFailed                     code "storage": the pattern store failed

REST errors and WebSocket ``error`` replies carry the same ``code`` and map to the same
class; ``status`` is the HTTP status, or ``None`` for a WebSocket reply. Errors of httpx and
websockets are re-raised as :class:`TransportError` with the original as ``__cause__``.
The client stands alone: it does not import the service's ``phantomtouch`` package, so
its errors are its own (the service's ``ParameterError`` is a ``ValueError`` too).
"""

from __future__ import annotations

from typing import Any


class ClientError(Exception):
    """Root of every error raised by phantomtouch_client."""


class ParameterError(ClientError, ValueError):
    """An argument is out of range or malformed; the message names it and its value."""


class TransportError(ClientError):
    """The server could not be reached, or its answer was not the protocol's."""


class ConnectionLost(TransportError):
    """The WebSocket closed before the reply to a request arrived.

    The request may or may not have reached the server.
    """


class ReplyTimeout(ClientError, TimeoutError):
    """The server did not answer a request in time."""


class ApiError(ClientError):
    """The server refused a request with an error body ``{code, message, fields}``."""

    def __init__(
        self,
        message: str,
        *,
        code: str,
        status: int | None = None,
        fields: list[dict[str, Any]] | None = None,
        request_id: str | int | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.code = code
        self.status = status
        self.fields = fields or []
        self.request_id = request_id

    def __str__(self) -> str:
        where = f"HTTP {self.status}" if self.status is not None else "WebSocket"
        return f"{self.message} ({where}, code {self.code!r})"


class InvalidRequest(ApiError, ParameterError):
    """A field is out of range or malformed; ``fields`` names each one."""


class MalformedMessage(ApiError):
    """The server could not read a WebSocket message (``invalid_json``, ``unknown_type``)."""


class Unauthorized(ApiError):
    """A token is required (the server is bound off loopback) and was missing or wrong."""


class NotFound(ApiError):
    """Unknown job, pattern or preset."""


class TooLarge(ApiError):
    """The body or message is over the server's size limit."""


class RateLimited(ApiError):
    """Too many requests or messages."""


class QuotaExceeded(RateLimited):
    """This client holds its share (contacts, voices, seconds of touch); the message names
    the quota. Retry when one of its touches has ended or a contact is lifted."""


class MethodNotAllowed(ApiError):
    """The route has no such method."""


class Busy(ApiError):
    """The engine's command queue is full; the command was not accepted. Retry later."""


class DeviceFailed(ApiError):
    """The service's sound card failed."""


class StorageFailed(ApiError):
    """The service's pattern store failed: its disk is full or its file damaged."""


_BY_CODE: dict[str, type[ApiError]] = {
    "invalid": InvalidRequest,
    "invalid_json": MalformedMessage,
    "unknown_type": MalformedMessage,
    "unauthorized": Unauthorized,
    "not_found": NotFound,
    "too_large": TooLarge,
    "rate_limited": RateLimited,
    "quota": QuotaExceeded,
    "method_not_allowed": MethodNotAllowed,
    "busy": Busy,
    "device": DeviceFailed,
    "storage": StorageFailed,
}

_BY_STATUS: dict[int, str] = {
    400: "invalid",
    401: "unauthorized",
    404: "not_found",
    405: "method_not_allowed",
    413: "too_large",
    422: "invalid",
    429: "rate_limited",
    503: "busy",
}


def api_error(
    code: str,
    message: str,
    *,
    status: int | None = None,
    fields: list[dict[str, Any]] | None = None,
    request_id: str | int | None = None,
) -> ApiError:
    """The exception for an error ``code`` (an unknown code gives a plain :class:`ApiError`)."""
    cls = _BY_CODE.get(code, ApiError)
    return cls(message, code=code, status=status, fields=fields, request_id=request_id)


def error_from_response(status: int, body: Any, text: str) -> ApiError:
    """The exception for a refused HTTP request, from its JSON body when it has one.

    ``body`` is the decoded JSON (or ``None``); ``text`` is the raw body, used when the
    server (or a proxy in front of it) answered without the protocol's error object.
    """
    error = body.get("error") if isinstance(body, dict) else None
    if isinstance(error, dict):
        code = str(error.get("code") or _BY_STATUS.get(status, "http_error"))
        message = str(error.get("message") or text or f"HTTP {status}")
        fields = error.get("fields")
        return api_error(
            code, message, status=status, fields=fields if isinstance(fields, list) else None
        )
    code = _BY_STATUS.get(status, "http_error")
    return api_error(code, text.strip()[:500] or f"HTTP {status}", status=status)
