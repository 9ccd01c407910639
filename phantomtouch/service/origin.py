"""Guards against web pages: the ``Host`` a request names, its ``Origin``, its body's type.

A browser on the user's machine is a client of 127.0.0.1 too, and every page it opens
can send requests there. Three checks keep such pages from driving the armband while
clients that are not browsers (game engines, the SDKs, curl) notice none of them:

- **Host** (:class:`HostOriginMiddleware`): a request is served only for a host name the
  service answers to (:class:`HostPolicy`). DNS rebinding points a page's own name at
  127.0.0.1, which makes its requests same-origin; their ``Host`` still carries that name.
- **Origin** (:class:`HostOriginMiddleware`): browsers send ``Origin`` with every
  WebSocket handshake and every request but a simple ``GET``; one is served only if it is
  the service's own (``http(s)://`` plus the request's ``Host``) or configured in
  ``cors_origins`` (:class:`OriginPolicy`).
- **Content type** (:class:`ContentTypeMiddleware`): a request body is accepted only as
  ``application/json``. A page can send ``text/plain``, form-encoded or untyped bodies to
  any host without asking (a CORS "simple request"); JSON needs a preflight, which the
  Origin check refuses.

Refusals answer with the service's error body (:mod:`phantomtouch.service.errors`: 421
``unknown_host``, 403 ``forbidden_origin``, 415 ``unsupported_media_type``; a WebSocket
handshake gets the same as its HTTP answer), are counted in ``/metrics``
(``phantomtouch_refused_requests_total{check, transport}``) and logged, the first time for
each refused value.
"""

from __future__ import annotations

import ipaddress
import json
import logging
from collections.abc import Iterable
from dataclasses import dataclass
from urllib.parse import urlsplit

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

from phantomtouch.service.errors import (
    WS_CLOSE_POLICY_VIOLATION,
    ForbiddenOriginError,
    ServiceError,
    UnknownHostError,
    UnsupportedMediaTypeError,
    describe,
)
from phantomtouch.service.limits import send_problem
from phantomtouch.service.metrics import Metrics

logger = logging.getLogger("phantomtouch.server.origin")

LOOPBACK_HOSTS = frozenset({"localhost", "127.0.0.1", "[::1]"})
"""Host names every service answers to."""
WILDCARD_BINDS = frozenset({"0.0.0.0", "[::]"})
"""Bind addresses that listen on every interface: any IP address is then the service's."""
JSON_MEDIA_TYPE = "application/json"
BODY_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
_MAX_LOGGED_VALUES = 256


def host_name(header: str) -> str:
    """The host part of a ``Host`` header, lower case, without port and trailing dot.

    ``"LocalHost:8000"`` -> ``"localhost"``, ``"[::1]:8000"`` -> ``"[::1]"``.
    """
    header = header.strip().lower()
    if header.startswith("["):
        return header[: header.find("]") + 1] or header
    return header.rsplit(":", 1)[0].rstrip(".")


def bracketed(address: str) -> str:
    """An address as it appears in a ``Host`` header: IPv6 in brackets, lower case."""
    address = address.strip().lower().strip("[]")
    return f"[{address}]" if ":" in address else address


def is_ip_literal(name: str) -> bool:
    """Whether ``name`` (from :func:`host_name`) is an IP address: IPv4, or IPv6 bracketed."""
    if ":" in name and not name.startswith("["):
        return False
    try:
        ipaddress.ip_address(name.strip("[]"))
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class HostPolicy:
    """The host names the service answers to.

    Always ``localhost``, ``127.0.0.1`` and ``[::1]``, the bound address and
    ``allowed_hosts``; bound to every interface (0.0.0.0 or ::), any IP address too: an
    address in the URL reaches exactly that address, so it cannot be rebound. ``*`` in
    ``allowed_hosts`` allows every name.
    """

    names: frozenset[str]
    any_ip_address: bool = False
    any_name: bool = False

    @classmethod
    def build(cls, bind_host: str, allowed_hosts: Iterable[str]) -> HostPolicy:
        bound = bracketed(bind_host)
        extra = {bracketed(host).rstrip(".") for host in allowed_hosts}
        return cls(
            names=LOOPBACK_HOSTS | {bound} | (extra - {"*"}),
            any_ip_address=bound in WILDCARD_BINDS,
            any_name="*" in extra,
        )

    def allows(self, name: str) -> bool:
        """Whether a request naming ``name`` (see :func:`host_name`) is served."""
        return self.any_name or name in self.names or (self.any_ip_address and is_ip_literal(name))


@dataclass(frozen=True)
class OriginPolicy:
    """The web page origins allowed: the service's own and ``cors_origins`` (``*``: all)."""

    configured: frozenset[str]

    @classmethod
    def build(cls, cors_origins: Iterable[str]) -> OriginPolicy:
        return cls(frozenset(origin.lower().rstrip("/") for origin in cors_origins))

    def allows(self, origin: str, host_header: str) -> bool:
        """Whether a request with ``Origin: origin`` and ``Host: host_header`` is served."""
        origin = origin.strip().lower()
        if "*" in self.configured or origin in self.configured:
            return True
        parts = urlsplit(origin)
        return (
            parts.scheme in ("http", "https")
            and parts.path == ""
            and parts.netloc == host_header.strip().lower()
        )


class Refusals:
    """Counts every refusal in ``/metrics`` and logs the first one of each refused value."""

    def __init__(self, metrics: Metrics) -> None:
        self.metrics = metrics
        self._logged: set[tuple[str, str, str]] = set()

    def record(self, check: str, scope: Scope, value: str | None, reason: str) -> None:
        transport = "websocket" if scope["type"] == "websocket" else "http"
        self.metrics.refused_requests.labels(check, transport).inc()
        key = (check, transport, str(value))
        if key not in self._logged and len(self._logged) < _MAX_LOGGED_VALUES:
            self._logged.add(key)
            logger.warning(
                "refused %s %s %s: %s (further refusals of this value are only counted "
                "in /metrics)",
                transport,
                scope.get("method", "handshake"),
                scope.get("path", ""),
                reason,
            )


async def refuse(scope: Scope, receive: Receive, send: Send, error: ServiceError) -> None:
    """Answer an HTTP request, or refuse a WebSocket handshake, with ``error``.

    The handshake gets the same HTTP status and error body where the server supports the
    ASGI ``websocket.http.response`` extension (uvicorn does), else a close with 1008.
    """
    problem = describe(error)
    if scope["type"] == "http":
        await send_problem(send, problem)
        return
    await receive()  # websocket.connect
    if "websocket.http.response" not in scope.get("extensions", {}):
        await send({"type": "websocket.close", "code": WS_CLOSE_POLICY_VIOLATION})
        return
    body = json.dumps(problem.body()).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    await send(
        {"type": "websocket.http.response.start", "status": problem.status_code, "headers": headers}
    )
    await send({"type": "websocket.http.response.body", "body": body})


class HostOriginMiddleware:
    """Refuse requests and handshakes for an unknown ``Host`` (421) or ``Origin`` (403)."""

    def __init__(
        self, app: ASGIApp, hosts: HostPolicy, origins: OriginPolicy, refusals: Refusals
    ) -> None:
        self.app = app
        self.hosts = hosts
        self.origins = origins
        self.refusals = refusals

    def check(self, scope: Scope) -> ServiceError | None:
        """The refusal of this request, or None to serve it."""
        headers = Headers(scope=scope)
        host = headers.get("host")
        if host is not None and not self.hosts.allows(host_name(host)):
            message = (
                f"host={host!r}: this service answers only to localhost, 127.0.0.1, [::1], "
                "its bound address and PHANTOMTOUCH_ALLOWED_HOSTS"
            )
            self.refusals.record("host", scope, host, message)
            return UnknownHostError(message, field="host", value=host)
        origin = headers.get("origin")
        if origin is not None and not self.origins.allows(origin, host or ""):
            message = (
                f"origin={origin!r}: web pages may call this service only from its own "
                "origin or one listed in PHANTOMTOUCH_CORS_ORIGINS"
            )
            self.refusals.record("origin", scope, origin, message)
            return ForbiddenOriginError(message, field="origin", value=origin)
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            error = self.check(scope)
            if error is not None:
                await refuse(scope, receive, send, error)
                return
        await self.app(scope, receive, send)


class ContentTypeMiddleware:
    """Refuse a request body not declared as ``application/json`` with 415.

    Requests without a body (``POST /stop``, a play without timing) need no type; a type
    that is declared must be JSON (parameters such as ``charset`` are allowed).
    """

    def __init__(self, app: ASGIApp, refusals: Refusals) -> None:
        self.app = app
        self.refusals = refusals

    def check(self, scope: Scope) -> ServiceError | None:
        """The refusal of this request, or None to serve it."""
        if scope["method"] not in BODY_METHODS:
            return None
        headers = Headers(scope=scope)
        declared = headers.get("content-type")
        if declared is None:
            length = headers.get("content-length")
            if "transfer-encoding" not in headers and (length is None or length.strip() == "0"):
                return None
            message = "content-type: missing; a request body must be sent as application/json"
        elif declared.split(";", 1)[0].strip().lower() == JSON_MEDIA_TYPE:
            return None
        else:
            message = (
                f"content-type={declared!r}: a request body is accepted only as application/json"
            )
        self.refusals.record("content_type", scope, declared, message)
        return UnsupportedMediaTypeError(message, field="content-type", value=declared)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            error = self.check(scope)
            if error is not None:
                await send_problem(send, describe(error))
                return
        await self.app(scope, receive, send)
