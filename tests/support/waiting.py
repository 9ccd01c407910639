"""Waiting in tests for what another thread, process or server does."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def wait_until(
    condition: Callable[[], T],
    timeout_s: float = 20.0,
    what: str = "the condition",
    interval_s: float = 0.02,
) -> T:
    """Poll ``condition`` every ``interval_s`` until it returns something truthy, and
    return that; fail (AssertionError naming ``what``) once ``timeout_s`` has passed.
    The condition is asked once more at the deadline, so a slow poll cannot miss it."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout_s} s: {what}")
        time.sleep(interval_s)
