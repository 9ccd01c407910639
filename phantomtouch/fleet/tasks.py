"""End an asyncio task for sure: cancel it again until it has ended."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

CANCEL_AGAIN_S = 0.05
"""How long :func:`cancel_until_done` waits for the task to end before it cancels it
again, s."""


async def cancel_until_done(task: asyncio.Task[Any]) -> None:
    """Cancel ``task`` until it has ended; an exception it ended with is dropped.

    One cancel is not enough for a task that waits on a NATS watch: ``asyncio.wait_for``
    (which the watch's ``updates`` uses) on Python 3.11 swallows a cancel that arrives
    just as an update does and returns the update, so the task goes on reading.
    """
    while not task.done():
        task.cancel()
        await asyncio.wait({task}, timeout=CANCEL_AGAIN_S)
    if not task.cancelled():
        with contextlib.suppress(Exception):
            task.result()
