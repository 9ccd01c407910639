"""The armband on the page: drawn to scale, and dragging on it drives the live contact."""

from __future__ import annotations

import itertools
import json
import math
from typing import Any

import httpx
import numpy as np
import pytest

from tests.web.support import (
    ArmbandOnPage,
    StateObserver,
    TouchScreen,
    screenshot,
    wait_until,
)

CONTACT_TOLERANCE_CM = 0.3
"""How far the server's contact may lie from the pointer: the page sends positions
rounded to CSS pixels (about 0.03 cm at this size), so this only allows for that."""


def loudest_channel(state: dict[str, Any]) -> int:
    """1-based channel with the highest level."""
    return int(np.argmax(state["levels"])) + 1


def contact_near(state: dict[str, Any], x_cm: float, y_cm: float) -> bool:
    return any(
        math.hypot(c["x_cm"] - x_cm, c["y_cm"] - y_cm) < CONTACT_TOLERANCE_CM
        for c in state["contacts"]
    )


def test_actuators_are_drawn_to_scale_with_labels_and_ends(
    page: Any, server: str, armband: ArmbandOnPage
) -> None:
    device = httpx.get(f"{server}/device").json()
    actuators = device["actuators"]
    labels = page.locator("#armband .actuator-label").all_text_contents()
    assert labels == [str(n) for n in range(1, len(actuators) + 1)]
    centres = np.array([armband.centre(n) for n in range(1, len(actuators) + 1)])
    cm = np.array([[a["y_cm"], a["x_cm"]] for a in actuators])
    # One scale for both axes: page distances are cm distances times a single factor.
    page_d = np.hypot(*(centres[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
    cm_d = np.hypot(*(cm[:, None, :] - cm[None, :, :]).transpose(2, 0, 1))
    scale = page_d[cm_d > 0] / cm_d[cm_d > 0]
    np.testing.assert_allclose(scale, scale.mean(), rtol=0.02)  # 2 %: sub-pixel rounding
    assert page.locator("#armband .triangles polygon").count() == len(device["triangles"])
    ends = page.locator("#armband .end-label").all_text_contents()
    assert any("wrist" in e for e in ends) and any("elbow" in e for e in ends)
    wrist, elbow = (page.locator("#armband .end-label").nth(i).bounding_box() for i in (0, 1))
    assert wrist is not None and elbow is not None
    first = min(actuators, key=lambda a: a["y_cm"])
    assert "wrist" in ends[0], "the wrist label sits at the y = 0 end"
    assert wrist["x"] < armband.centre(actuators.index(first) + 1)[0] < elbow["x"]
    assert page.locator("#st-backend").inner_text() == device["backend"]
    assert page.locator("#st-rate").inner_text().startswith(f"{device['sample_rate_hz']:,}")


def test_the_status_bar_says_what_an_underrun_is_on_this_output(page: Any, server: str) -> None:
    device = httpx.get(f"{server}/device").json()
    meaning = page.locator("#st-underruns").locator("..").get_attribute("title") or ""
    no_card = device["backend"] != "sounddevice"
    assert ("No sound card" in meaning) is no_card, meaning
    if no_card:  # the null sink's rule: a block more than one period late
        period_ms = 1000 * device["block_frames"] / device["sample_rate_hz"]
        assert f"more than one block ({period_ms:.1f} ms) late" in meaning, meaning


def test_drag_moves_the_phantom_from_actuator_4_to_actuator_5(
    page: Any, armband: ArmbandOnPage, observer: StateObserver
) -> None:
    start = observer.mark()
    x4, y4 = armband.centre(4)
    x5, y5 = armband.centre(5)
    page.mouse.move(x4, y4)
    page.mouse.down()
    at_4 = observer.wait_for(
        lambda s: contact_near(s, 0.0, 14.4) and loudest_channel(s) == 4,
        since=start,
        what="contact at actuator 4 with channel 4 loudest",
    )
    assert at_4["active_voices"] >= 1
    page.wait_for_function(
        "() => Number(document.querySelector('[data-actuator=\"4\"]').dataset.level) > 0"
    )
    screenshot(page, "drag_at_actuator_4")

    steps = 24
    for i in range(1, steps + 1):
        f = i / steps
        page.mouse.move(x4 + f * (x5 - x4), y4 + f * (y5 - y4))
        page.wait_for_timeout(25)
    at_5 = observer.wait_for(
        lambda s: contact_near(s, 3.8, 0.0) and loudest_channel(s) == 5,
        since=start,
        what="contact at actuator 5 with channel 5 loudest",
    )
    assert at_5["levels"][3] < at_4["levels"][3], "channel 4 fell as the phantom left it"
    screenshot(page, "drag_at_actuator_5")

    # The server saw the path, not just its ends: positions along the straight line from
    # actuator 4 to actuator 5, in order.
    seen = [
        (c["x_cm"], c["y_cm"])
        for s in observer.since(start)
        for c in s["contacts"]
        if c["contact"].startswith("web-")
    ]
    ys = [y for _, y in seen]
    assert len({round(y, 1) for y in ys}) >= 5, f"too few distinct positions: {seen}"
    assert all(b <= a + 1e-6 for a, b in itertools.pairwise(ys)), "y only decreases"
    for x, y in seen:
        assert x == pytest.approx(3.8 * (14.4 - y) / 14.4, abs=CONTACT_TOLERANCE_CM)

    lifted = observer.mark()
    page.mouse.up()
    observer.wait_for(
        lambda s: not s["contacts"] and s["active_voices"] == 0,
        since=lifted,
        what="no contacts and no voices after lift-off",
    )


def test_keyboard_touches_moves_and_lifts(
    page: Any, armband: ArmbandOnPage, observer: StateObserver
) -> None:
    page.focus("#armband")
    start = observer.mark()
    page.keyboard.press("Enter")
    first = observer.wait_for(lambda s: bool(s["contacts"]), since=start, what="keyboard contact")
    y0 = first["contacts"][0]["y_cm"]
    for _ in range(5):
        page.keyboard.press("ArrowRight")
    observer.wait_for(
        lambda s: bool(s["contacts"]) and s["contacts"][0]["y_cm"] == pytest.approx(y0 + 1.0),
        since=start,
        what="contact moved 1 cm towards the elbow",
    )
    lifted = observer.mark()
    page.keyboard.press("Enter")
    observer.wait_for(lambda s: not s["contacts"], since=lifted, what="keyboard lift-off")


def test_moves_are_sent_once_per_animation_frame_and_the_latest_wins(
    page: Any, armband: ArmbandOnPage
) -> None:
    sent: list[dict[str, Any]] = []
    page.on(
        "websocket",
        lambda ws: ws.on("framesent", lambda payload: sent.append(json.loads(payload))),
    )
    page.reload()
    page.wait_for_selector("#connection[data-state=connected]")
    page.mouse.move(*armband.centre(2))
    page.mouse.down()
    wait_until(page, lambda: any(m["type"] == "down" for m in sent))
    assert [m["type"] for m in sent if m["type"] in ("down", "move")] == ["down"]
    targets = [armband.point(1.9, 4.8 + 0.2 * i) for i in range(1, 41)]
    # Forty pointer moves within one task, so within one animation frame.
    page.evaluate(
        """targets => {
            const svg = document.getElementById("armband");
            for (const [x, y] of targets) {
                svg.dispatchEvent(new PointerEvent("pointermove", {
                    pointerId: 1, pointerType: "mouse", isPrimary: true, bubbles: true,
                    clientX: x, clientY: y,
                }));
            }
        }""",
        targets,
    )
    page.evaluate("() => new Promise((r) => requestAnimationFrame(() => setTimeout(r, 50)))")
    moves = [m for m in sent if m["type"] == "move"]
    assert len(moves) == 1, moves
    assert moves[0]["x_cm"] == pytest.approx(1.9, abs=0.05)
    assert moves[0]["y_cm"] == pytest.approx(4.8 + 0.2 * 40, abs=0.05)
    page.mouse.up()
    wait_until(page, lambda: any(m["type"] == "up" for m in sent))
    ups = [m for m in sent if m["type"] == "up"]
    assert [m["contact"] for m in ups] == [moves[0]["contact"]]


def test_a_refused_touch_is_shown_and_its_moves_are_not_sent(
    page: Any, armband: ArmbandOnPage, observer: StateObserver
) -> None:
    page.fill("#live-freq", "0")
    start = observer.mark()
    page.mouse.move(*armband.centre(2))
    page.mouse.down()
    alert = page.locator("#alerts [role=alert]")
    alert.first.wait_for()
    assert "freq_hz" in alert.first.inner_text()
    for i in range(1, 11):
        page.mouse.move(*armband.point(0.2 * i, 4.8))
        page.wait_for_timeout(20)
    page.mouse.up()
    page.wait_for_timeout(300)
    assert alert.count() == 1, "one refusal, one message: no errors for the moves after it"
    assert all(not s["contacts"] for s in observer.since(start))


def test_two_fingers_are_two_contacts(
    page: Any, armband: ArmbandOnPage, observer: StateObserver
) -> None:
    screen = TouchScreen(page)
    start = observer.mark()
    screen.touch({1: armband.centre(1)})
    screen.touch({1: armband.centre(1), 2: armband.centre(8)})
    both = observer.wait_for(
        lambda s: len(s["contacts"]) == 2 and s["levels"][0] > 0 and s["levels"][7] > 0,
        since=start,
        what="two contacts, at actuators 1 and 8",
    )
    positions = sorted((round(c["x_cm"], 1), round(c["y_cm"], 1)) for c in both["contacts"])
    assert positions == [(0.0, 0.0), (3.8, 14.4)]
    assert all(c["contact"].startswith("web-") for c in both["contacts"])
    # The page draws both as its own (the observer's state calls them another's).
    page.wait_for_function(
        "() => document.querySelectorAll('.server-contact:not(.other)').length === 2"
    )
    screenshot(page, "two_fingers")
    screen.touch({2: armband.centre(8)})
    observer.wait_for(
        lambda s: [round(c["y_cm"], 1) for c in s["contacts"]] == [14.4],
        since=start,
        what="only the second finger left",
    )
    lifted = observer.mark()
    screen.touch({})
    observer.wait_for(lambda s: not s["contacts"], since=lifted, what="both fingers lifted")
