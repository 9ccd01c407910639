"""The task serving one WebSocket session (``/ws`` and the gateway's), and the yield of
its slot that ends it.

The admission gives a session's slot to a newcomer in whatever thread opened the newcomer
(:data:`~phantomtouch.service.admission.YieldCallback`); the session's task is cancelled
on its own event loop, and the session closes 1013 with the reason. A cancellation that
is no yield (the server shutting down) goes on as a cancellation.
"""

from __future__ import annotations

import asyncio
from typing import Any

from phantomtouch.service.errors import WS_CLOSE_TRY_AGAIN_LATER

MAX_REASON_CHARS = 120
"""The most of a yield's reason a close frame carries (a close frame's reason is at most
123 bytes)."""


class ServingTask:
    """The task serving one session, once it serves, and why its slot was taken."""

    def __init__(self) -> None:
        self._task: asyncio.Task[Any] | None = None
        self.yielded: str | None = None
        """The reason the slot was taken, or None while it is the session's."""

    def start(self) -> None:
        """The current task serves the session (event loop)."""
        self._task = asyncio.current_task()

    @property
    def serving(self) -> bool:
        """Whether a task serves the session (:meth:`start` was called). Any thread."""
        return self._task is not None

    def yield_slot(self, reason: str) -> None:
        """The admission took the session's slot (it closed the source): cancel the task
        serving it, which then closes 1013 with ``reason``; nothing to end while the
        session is not serving yet (any thread; it returns at once: a
        :data:`~phantomtouch.service.admission.YieldCallback`)."""
        task = self._task
        if task is None:
            return
        self.yielded = reason[:MAX_REASON_CHARS]
        task.get_loop().call_soon_threadsafe(task.cancel)

    def close_frame(self, cancelled: asyncio.CancelledError) -> tuple[int, str]:
        """The close code and reason of a yield (1013), for the serving task that caught
        ``cancelled``.

        Raises
        ------
        asyncio.CancelledError
            ``cancelled`` again when it was no yield: the cancellation goes on.
        """
        if self.yielded is None:
            raise cancelled
        return WS_CLOSE_TRY_AGAIN_LATER, self.yielded
