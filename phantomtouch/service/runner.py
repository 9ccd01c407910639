"""Run an ASGI application under uvicorn as a command: one line per failure, exit status.

uvicorn reports a failed start-up or shut-down with the whole traceback and ends with
status 3, and ends a SIGTERM'd process by raising the signal again (status -15). A
command says what failed in one line and exits 0, 1 or 2. :func:`run_app` keeps what
uvicorn does well (its signal handling, the graceful shut-down) and changes that:

- an exception of the application's start-up or shut-down (the engine, the pattern
  store, the fleet's NATS connection, a capture WAV that cannot be written) is kept
  from uvicorn's log and raised from :func:`run_app` once uvicorn has returned, as a
  :class:`~phantomtouch.errors.PhantomTouchError` the command line prints in one line;
- SIGTERM and SIGINT shut the application down and :func:`run_app` returns normally.
"""

from __future__ import annotations

import logging
import signal
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from phantomtouch.errors import PhantomTouchError

Message = MutableMapping[str, Any]
ASGIApp = Callable[
    [Message, Callable[[], Awaitable[Message]], Callable[[Message], Awaitable[None]]],
    Awaitable[None],
]

_UVICORN_FAILURE_LINES = (
    "Application startup failed. Exiting.",
    "Application shutdown failed. Exiting.",
)


class DropFailureLines(logging.Filter):
    """Drops uvicorn's "Application startup failed" lines: the command prints its own."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() not in _UVICORN_FAILURE_LINES


class _Lifespan:
    """The application, with the exceptions of its lifespan kept in ``failures``."""

    def __init__(self, app: ASGIApp, failures: list[BaseException]) -> None:
        self.app = app
        self.failures = failures

    async def __call__(
        self,
        scope: Message,
        receive: Callable[[], Awaitable[Message]],
        send: Callable[[Message], Awaitable[None]],
    ) -> None:
        if scope["type"] != "lifespan":
            await self.app(scope, receive, send)
            return
        started = False

        async def quiet_send(message: Message) -> None:
            nonlocal started
            kind = message["type"]
            if kind == "lifespan.startup.complete":
                started = True
            if kind == "lifespan.startup.failed":  # the traceback is not for the log
                message = {"type": kind, "message": ""}
            if kind == "lifespan.shutdown.failed":  # said once, by the command
                message = {"type": "lifespan.shutdown.complete"}
            await send(message)

        try:
            await self.app(scope, receive, quiet_send)
        except Exception as exc:
            self.failures.append(exc)
            if not started:
                raise  # uvicorn knows the start-up failed, and stops


def run_app(app: Any, **options: Any) -> None:
    """Serve ``app`` until SIGTERM or SIGINT; ``options`` go to ``uvicorn.Config``.

    Raises
    ------
    PhantomTouchError
        The application's start-up or shut-down failed (its own error, or any other
        exception named by its type), or uvicorn could not start.
    """
    import uvicorn

    failures: list[BaseException] = []
    server = uvicorn.Server(uvicorn.Config(_Lifespan(app, failures), **options))
    # uvicorn raises the signal again after its graceful shut-down: ignored, the command
    # returns and exits 0
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        server.run()
    except KeyboardInterrupt:
        pass
    except SystemExit:  # uvicorn's way of saying that it could not start
        if not failures:
            raise PhantomTouchError("the server did not start (see the line above)") from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    if failures:
        failure = failures[0]
        if isinstance(failure, PhantomTouchError):
            raise failure
        raise PhantomTouchError(f"{type(failure).__name__}: {failure}") from failure
