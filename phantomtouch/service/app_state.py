"""What an app sets up at start-up and keeps in ``app.state`` for its routes to read back
(the touch service's :class:`~phantomtouch.service.running.Service`, a fleet gateway)."""

from __future__ import annotations

from typing import TypeVar

from starlette.requests import HTTPConnection

Held = TypeVar("Held")


def app_state(connection: HTTPConnection, name: str, kind: type[Held]) -> Held:
    """``app.state.<name>`` of the app serving ``connection``.

    Called on the event loop by route dependencies and WebSocket endpoints.

    Parameters
    ----------
    connection
        An HTTP request or a WebSocket of the app.
    name
        The attribute the app's lifespan set.
    kind
        The class of what it holds.

    Raises
    ------
    AttributeError
        The app has not started (its lifespan has not set ``name``).
    TypeError
        What the app holds as ``name`` is not a ``kind``.
    """
    held = getattr(connection.app.state, name)
    if not isinstance(held, kind):
        raise TypeError(f"app.state.{name} is a {type(held).__name__}, not a {kind.__name__}")
    return held
