"""What the web page tests share: a state observer, console error collection, screenshots,
and where armband points lie on the page."""

from __future__ import annotations

import json
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO / "artifacts" / "web"
VIEWPORT = {"width": 1440, "height": 1000}


class ConsoleErrors:
    """Console messages of type error and uncaught page errors, with expected ones allowed."""

    def __init__(self) -> None:
        self.messages: list[str] = []
        self.allowed: list[re.Pattern[str]] = []

    def allow(self, pattern: str) -> None:
        self.allowed.append(re.compile(pattern))

    def unexpected(self) -> list[str]:
        return [m for m in self.messages if not any(p.search(m) for p in self.allowed)]


def screenshot(page: Any, name: str) -> Path:
    """Save a full-page screenshot as artifacts/web/<name>.png."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', name)}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


class StateObserver:
    """A second WebSocket client of the service that records every `state` message."""

    def __init__(self, socket: Any) -> None:
        self.socket = socket
        self.states: list[dict[str, Any]] = []
        self.lock = threading.Lock()
        self.closed = threading.Event()
        self.socket.send(json.dumps({"type": "hello", "client": "web-test-observer"}))
        self.socket.send(json.dumps({"type": "subscribe", "rate_hz": 60}))
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.pinger = threading.Thread(target=self._ping, daemon=True)
        self.pinger.start()

    def _read(self) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            for text in self.socket:
                message = json.loads(text)
                if message.get("type") == "state":
                    with self.lock:
                        self.states.append(message)
        except ConnectionClosed:
            pass
        finally:
            self.closed.set()

    def _ping(self) -> None:
        from websockets.exceptions import ConnectionClosed

        while not self.closed.wait(0.5):
            try:
                self.socket.send(json.dumps({"type": "ping"}))
            except ConnectionClosed:
                return

    def mark(self) -> int:
        """Index of the next state message: wait_for(..., since=mark()) ignores older ones."""
        with self.lock:
            return len(self.states)

    def since(self, index: int) -> list[dict[str, Any]]:
        with self.lock:
            return list(self.states[index:])

    def wait_for(
        self,
        predicate: Callable[[dict[str, Any]], bool],
        *,
        since: int = 0,
        timeout_s: float = 5.0,
        what: str = "a matching state",
    ) -> dict[str, Any]:
        """The first state (from index `since`) for which predicate holds; fails after timeout."""
        deadline = time.monotonic() + timeout_s
        checked = since
        while True:
            with self.lock:
                fresh = self.states[checked:]
            for state in fresh:
                if predicate(state):
                    return state
            checked += len(fresh)
            if time.monotonic() > deadline:
                last = self.since(max(since, checked - 1))
                pytest.fail(f"no {what} within {timeout_s:g} s; last state: {last[-1:]}")
            time.sleep(0.02)


class ArmbandOnPage:
    """Where points of the armband (cm) are on the page (CSS px)."""

    def __init__(self, page: Any) -> None:
        self.page = page

    def point(self, x_cm: float, y_cm: float) -> tuple[float, float]:
        x, y = self.page.evaluate(
            """([x, y]) => {
                const svg = document.getElementById("armband");
                const p = new DOMPoint(y, x).matrixTransform(svg.getScreenCTM());
                return [p.x, p.y];
            }""",
            [x_cm, y_cm],
        )
        return float(x), float(y)

    def centre(self, actuator: int) -> tuple[float, float]:
        box = self.page.locator(f'#armband [data-actuator="{actuator}"] circle.body').bounding_box()
        assert box is not None, f"actuator {actuator} is not drawn"
        return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2


class TouchScreen:
    """Fingers on a touch screen: Chrome DevTools touch events, which the page receives as
    real pointer events of type touch."""

    def __init__(self, page: Any) -> None:
        self.cdp = page.context.new_cdp_session(page)
        self.cdp.send("Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 5})
        self.down: set[int] = set()
        self.at: dict[int, tuple[float, float]] = {}

    def touch(self, fingers: dict[int, tuple[float, float]]) -> None:
        """Fingers now on the screen (id -> page position); those left out are lifted.

        DevTools takes the fingers that go down with touchStart, those that go up with
        touchEnd, and every finger still down with touchMove.
        """

        def points(ids: set[int], at: dict[int, tuple[float, float]]) -> list[dict[str, Any]]:
            return [{"x": at[i][0], "y": at[i][1], "id": i} for i in sorted(ids)]

        lifted = self.down - set(fingers)
        if lifted:
            at = {i: self.at[i] for i in lifted}
            self.cdp.send(
                "Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": points(lifted, at)}
            )
        new = set(fingers) - self.down
        if new:
            self.cdp.send(
                "Input.dispatchTouchEvent",
                {"type": "touchStart", "touchPoints": points(new, fingers)},
            )
        moved = {i for i in set(fingers) & self.down if fingers[i] != self.at[i]}
        if moved:
            self.cdp.send(
                "Input.dispatchTouchEvent",
                {"type": "touchMove", "touchPoints": points(set(fingers), fingers)},
            )
        self.down = set(fingers)
        self.at = dict(fingers)


def wait_until(page: Any, condition: Callable[[], bool], timeout_s: float = 5.0) -> None:
    """Let the page run until `condition()` holds (Playwright events arrive meanwhile)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        page.wait_for_timeout(20)
