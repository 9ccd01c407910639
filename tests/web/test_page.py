"""The page as a whole: stop button and Escape, reconnection, labels, narrow screens."""

from __future__ import annotations

import re
from typing import Any

from tests.web.support import VIEWPORT, ArmbandOnPage, StateObserver, TouchScreen, screenshot

LONG_PRESET = "exp1/noise-low-v3"
"""Up and down the band at 3 cm/s: about 12 s, long enough to be stopped."""


def play_long_pattern(page: Any) -> None:
    page.select_option("#source", f"preset:{LONG_PRESET}")
    page.wait_for_function(
        "name => document.querySelector('#source-summary').textContent !== ''"
        " && document.getElementById('source').value === 'preset:' + name",
        arg=LONG_PRESET,
    )
    page.click("#play")


def test_stop_button_ends_every_pattern_and_contact(
    page: Any, armband: ArmbandOnPage, observer: StateObserver
) -> None:
    start = observer.mark()
    play_long_pattern(page)
    finger = TouchScreen(page)
    finger.touch({1: armband.centre(6)})
    observer.wait_for(
        lambda s: s["active_voices"] >= 2 and len(s["contacts"]) == 1,
        since=start,
        what="a pattern and a finger's contact both active",
    )
    stopped = observer.mark()
    page.click("#stop")
    observer.wait_for(
        lambda s: s["active_voices"] == 0 and not s["contacts"],
        since=stopped,
        timeout_s=3.0,
        what="silence after the stop button",
    )
    # The finger is still down: moving it must not bring the contact back.
    finger.touch({1: armband.centre(7)})
    page.wait_for_timeout(300)
    finger.touch({})
    assert_silent_for(page, observer, 0.3)
    assert page.inner_text("#job") == "Stopped."


def test_escape_ends_every_pattern_and_contact(
    page: Any, armband: ArmbandOnPage, observer: StateObserver
) -> None:
    start = observer.mark()
    play_long_pattern(page)
    page.mouse.move(*armband.centre(6))
    page.mouse.down()
    observer.wait_for(
        lambda s: s["active_voices"] >= 2 and len(s["contacts"]) == 1,
        since=start,
        what="a pattern and a mouse contact both active",
    )
    stopped = observer.mark()
    page.keyboard.press("Escape")
    observer.wait_for(
        lambda s: s["active_voices"] == 0 and not s["contacts"],
        since=stopped,
        timeout_s=3.0,
        what="silence after Escape",
    )
    page.mouse.move(*armband.centre(7))
    page.wait_for_timeout(300)
    page.mouse.up()
    assert_silent_for(page, observer, 0.3)

    start = observer.mark()
    page.click("#play")
    observer.wait_for(lambda s: s["active_voices"] >= 1, since=start, what="playing again")
    page.focus("#speed")  # Escape works wherever the focus is, in a text field too
    stopped = observer.mark()
    page.keyboard.press("Escape")
    observer.wait_for(
        lambda s: s["active_voices"] == 0, since=stopped, timeout_s=3.0, what="silence"
    )


def assert_silent_for(page: Any, observer: StateObserver, seconds: float) -> None:
    later = observer.mark()
    page.wait_for_timeout(seconds * 1000)
    states = observer.since(later)
    assert states, "state messages keep coming"
    assert all(s["active_voices"] == 0 and not s["contacts"] for s in states)


def test_stop_button_stays_visible_when_scrolled(page: Any) -> None:
    page.set_viewport_size({"width": 900, "height": 600})
    page.mouse.wheel(0, 3000)
    page.wait_for_timeout(200)
    box = page.locator("#stop").bounding_box()
    assert box is not None and box["y"] >= 0 and box["y"] + box["height"] <= 600
    page.set_viewport_size(VIEWPORT)


def test_websocket_reconnects_after_a_drop(page: Any, server: str) -> None:
    connections: list[Any] = []

    def route(ws: Any) -> None:
        ws.connect_to_server()
        connections.append(ws)

    page.route_web_socket(re.compile(r"/ws$"), route)
    page.reload()
    page.wait_for_selector("#connection[data-state=connected]")
    assert len(connections) == 1
    connections[0].close(code=1012, reason="service restart")
    page.wait_for_selector("#connection[data-state=disconnected]")
    assert "retrying" in page.inner_text("#connection")
    page.wait_for_selector("#connection[data-state=connected]", timeout=10_000)
    assert len(connections) == 2
    page.wait_for_function("() => document.getElementById('st-voices').textContent !== '–'")


def test_every_control_has_an_accessible_name(page: Any) -> None:
    unnamed = page.evaluate(
        """() => [...document.querySelectorAll("input, select, button, textarea, svg[tabindex]")]
            .filter((el) => !(el.labels && el.labels.length)
                && !el.getAttribute("aria-label")
                && !el.getAttribute("aria-labelledby")
                && !(el.tagName === "BUTTON" && el.textContent.trim()))
            .map((el) => el.outerHTML.slice(0, 80))"""
    )
    assert unnamed == []


def test_narrow_screen_layout(page: Any) -> None:
    page.set_viewport_size({"width": 420, "height": 900})
    page.wait_for_timeout(300)
    width = page.evaluate("() => document.documentElement.scrollWidth")
    assert width <= 420, "nothing overflows sideways"
    screenshot(page, "narrow_screen")
    page.set_viewport_size(VIEWPORT)


def test_nothing_is_fetched_from_other_hosts(page: Any, server: str) -> None:
    urls: list[str] = []
    page.on("request", lambda request: urls.append(request.url))
    page.reload()
    page.wait_for_selector("body[data-ready=true]")
    page.wait_for_selector("#connection[data-state=connected]")
    assert any(u.endswith("/static/app.js") for u in urls)
    origin = server.replace("http://", "")
    foreign = [
        u for u in urls if not u.startswith(("data:", f"http://{origin}/", f"ws://{origin}/"))
    ]
    assert foreign == []
