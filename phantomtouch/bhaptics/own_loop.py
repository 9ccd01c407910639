"""The bHaptics stand-in on a thread and event loop of its own (``docs/lane.md``).

A game's frames move live contacts (:mod:`~phantomtouch.bhaptics.frames`). Read by the
service's event loop, they would wait behind every HTTP request it serves; here the
stand-in's listener (:mod:`~phantomtouch.bhaptics.listener`, unchanged) runs in its own
thread, which asks for real-time priority where the user may
(:mod:`~phantomtouch.service.thread_priority`), with its own asyncio loop. What it shares
with the rest of the service is made for any thread: the engine's front, the connection
caps, the metrics registry.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from phantomtouch.bhaptics.listener import attach as attach_listener
from phantomtouch.service.thread_priority import raise_thread_priority

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

Started = concurrent.futures.Future[tuple[asyncio.AbstractEventLoop, asyncio.Event]]


@asynccontextmanager
async def attach(service: Service) -> AsyncIterator[None]:
    """What ``create_app(attach=...)`` enters when ``bhaptics_listen`` is set: the
    listener started in its own thread (the service's event loop waits until it listens,
    and re-raises what stopped it from starting), closed before the service stops."""
    started: Started = concurrent.futures.Future()
    thread = threading.Thread(
        target=_serve, args=(service, started), name="phantomtouch-bhaptics", daemon=True
    )
    thread.start()
    try:
        loop, stop = await asyncio.wrap_future(started)
    except BaseException:
        await asyncio.to_thread(thread.join)
        raise
    try:
        yield
    finally:
        loop.call_soon_threadsafe(stop.set)
        await asyncio.to_thread(thread.join)


def _serve(service: Service, started: Started) -> None:
    """The stand-in's thread: its loop runs the listener until told to stop (the loop's
    worker threads run at ordinary priority: ``SCHED_RESET_ON_FORK``)."""
    raise_thread_priority("the bHaptics stand-in")
    try:
        asyncio.run(_listen(service, started))
    except BaseException as exc:
        if not started.done():
            started.set_exception(exc)
            return
        raise


async def _listen(service: Service, started: Started) -> None:
    stop = asyncio.Event()
    async with attach_listener(service):
        started.set_result((asyncio.get_running_loop(), stop))
        await stop.wait()
