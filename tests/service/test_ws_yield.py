"""A session's serving task: a yield of its slot ends it with 1013 and the reason; any
other cancellation goes on as a cancellation."""

from __future__ import annotations

import asyncio
import threading

import pytest

from phantomtouch.service.errors import WS_CLOSE_TRY_AGAIN_LATER
from phantomtouch.service.ws_yield import MAX_REASON_CHARS, ServingTask


async def _serve(serving: ServingTask, started: asyncio.Event) -> tuple[int, str]:
    """A session's run: serve until cancelled, then the close frame of a yield."""
    try:
        serving.start()
        started.set()
        await asyncio.sleep(60.0)
    except asyncio.CancelledError as cancelled:
        return serving.close_frame(cancelled)
    raise AssertionError("served on past a minute")


def test_a_yield_from_another_thread_closes_the_session_1013_with_its_reason() -> None:
    async def main() -> tuple[int, str]:
        serving = ServingTask()
        started = asyncio.Event()
        task = asyncio.create_task(_serve(serving, started))
        await started.wait()
        reason = "ws slots full: made room for a newcomer " * 10
        other = threading.Thread(target=serving.yield_slot, args=(reason,))
        other.start()
        other.join()
        return await asyncio.wait_for(task, 5.0)

    code, reason = asyncio.run(main())
    assert code == WS_CLOSE_TRY_AGAIN_LATER
    assert len(reason) == MAX_REASON_CHARS
    assert reason.startswith("ws slots full: made room for a newcomer")


def test_a_cancellation_that_is_no_yield_goes_on() -> None:
    async def main() -> None:
        serving = ServingTask()
        started = asyncio.Event()
        task = asyncio.create_task(_serve(serving, started))
        await started.wait()
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        assert task.cancelled()
        assert serving.yielded is None

    asyncio.run(main())


def test_a_yield_before_the_session_serves_ends_nothing() -> None:
    serving = ServingTask()
    assert not serving.serving
    serving.yield_slot("too early")
    assert serving.yielded is None
    assert not serving.serving
