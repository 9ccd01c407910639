"""What the blocking and the asyncio REST clients share, free of I/O.

:class:`ClientBase` holds a client's settings and decides, for both
:class:`~phantomtouch_client.Client` and :class:`~phantomtouch_client.AsyncClient`, the
call a touch makes, the arguments of its request, whether a refusal is retried
(after how many seconds) and the exception a failed request raises. :func:`ws_url` and
:func:`auth_headers` give the WebSocket address and the token header a session uses too.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import UTC, datetime
from email.utils import parsedate_to_datetime
from typing import Any

import httpx

from phantomtouch_client import _calls
from phantomtouch_client.errors import ParameterError, ReplyTimeout, TransportError
from phantomtouch_client.models import Job, PatternArg, fleet_touch_request, touch_request

DEFAULT_URL = "http://127.0.0.1:8000"


def ws_url(base_url: str) -> str:
    """The WebSocket address ``/ws`` of a service at ``base_url`` (http -> ws, https -> wss)."""
    url = httpx.URL(base_url)
    scheme = {"http": "ws", "https": "wss"}.get(url.scheme, url.scheme)
    return str(url.copy_with(scheme=scheme, path=url.path.rstrip("/") + "/ws"))


def auth_headers(token: str | None) -> dict[str, str]:
    """The header that carries the service token, if there is one."""
    return {"Authorization": f"Bearer {token}"} if token else {}


RETRY_STATUSES = frozenset({429, 503})
"""Refusals that say "not now": too many requests, the engine busy (not accepted)."""


def retry_after_s(response: httpx.Response) -> float | None:
    """Seconds ``Retry-After`` asks to wait (a number or an HTTP date), None without one."""
    value = response.headers.get("Retry-After")
    if value is None:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        when = parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return None
    return max(0.0, (when - datetime.now(UTC)).total_seconds())


class ClientBase:
    """The settings of a REST client and the decisions its blocking and asyncio forms share.

    Parameters
    ----------
    base_url : str
        The service's address; a trailing ``/`` is dropped.
    token : str or None
        The service token, sent as ``Authorization: Bearer``.
    timeout_s : float
        Longest wait for each request, s.
    retries : int, >= 0
        Most retries of a 429 or 503 answer.
    max_retry_wait_s : float, >= 0
        Longest ``Retry-After`` that is waited for, s; a longer one is raised at once.
    """

    def __init__(
        self,
        base_url: str,
        token: str | None,
        timeout_s: float,
        retries: int,
        max_retry_wait_s: float,
    ) -> None:
        if retries < 0 or max_retry_wait_s < 0:
            raise ParameterError(
                f"retries={retries!r} and max_retry_wait_s={max_retry_wait_s!r} must be >= 0"
            )
        self.base_url = base_url.rstrip("/")
        self.token = token
        self.timeout_s = timeout_s
        self.retries = retries
        self.max_retry_wait_s = max_retry_wait_s

    def _retry_wait_s(self, response: httpx.Response, attempt: int) -> float | None:
        """How long to wait before retrying ``response``, or None to give up."""
        if response.status_code not in RETRY_STATUSES or attempt >= self.retries:
            return None
        wait_s = retry_after_s(response)
        if wait_s is None or wait_s > self.max_retry_wait_s:
            return None
        return wait_s

    def _request_args(self, call: _calls.Call[Any]) -> dict[str, Any]:
        args: dict[str, Any] = {"headers": {"Accept": call.accept}}
        if call.body is not None:
            args["json"] = call.body
        if call.params is not None:
            args["params"] = dict(call.params)
        return args

    @staticmethod
    def _failed(call: _calls.Call[Any], exc: httpx.HTTPError) -> Exception:
        what = f"{call.method} {call.path}"
        if isinstance(exc, httpx.TimeoutException):
            return ReplyTimeout(f"{what}: no answer in time ({exc})")
        return TransportError(f"{what}: {exc}")

    @staticmethod
    def _touch_call(
        pattern: PatternArg,
        *,
        preset: str | None,
        stored: str | None,
        overrides: Mapping[str, Any] | None,
        start_in_ms: float | None,
        start_at_s: float | None,
        armband: str | None,
        start_at_unix_s: float | None,
    ) -> _calls.Call[Job]:
        """``POST /touch`` (or an armband's, through a fleet gateway) with its body checked."""
        body = fleet_touch_request(
            touch_request(
                pattern,
                preset=preset,
                stored=stored,
                overrides=overrides,
                start_in_ms=start_in_ms,
                start_at_s=start_at_s,
            ),
            start_at_unix_s,
        )
        return _calls.touch(body, armband)
