"""The page at a desktop width (1280 px) and a phone's (390 px): every select shows its
longest option whole, "Stop all" stays on one line, the armband's axis labels stay
readable, and a refused save says so without losing the drawn path."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.web.support import VIEWPORT, ArmbandOnPage, ConsoleErrors, screenshot

WIDTHS_PX = (1280, 390)
MIN_LABEL_PX = 11.0
"""Smallest axis label height, CSS px (the labels were 8 px high at 390 px)."""


@pytest.fixture(params=WIDTHS_PX, ids=lambda w: f"{w}px")
def sized(page: Any, request: pytest.FixtureRequest) -> Iterator[tuple[Any, int]]:
    width = int(request.param)
    page.set_viewport_size({"width": width, "height": 900})
    page.wait_for_function(f"() => document.documentElement.clientWidth === {width}")
    page.wait_for_timeout(200)  # the armband's labels follow its resize
    yield page, width
    page.set_viewport_size(VIEWPORT)


def test_every_select_shows_its_longest_option(sized: tuple[Any, int]) -> None:
    page, width = sized
    # The width each option needs, from a hidden copy of the select that holds only that
    # option and sizes itself to it (CSS field-sizing: content).
    clipped = page.evaluate(
        """() => [...document.querySelectorAll('select')].filter((s) => s.offsetParent)
            .flatMap((select) => [...select.options].map((option) => {
              const probe = select.cloneNode(false);
              probe.style.cssText = 'field-sizing: content; width: auto; position: absolute;'
                + ' visibility: hidden';
              probe.appendChild(option.cloneNode(true));
              document.body.appendChild(probe);
              const needed = probe.getBoundingClientRect().width;
              probe.remove();
              const has = select.getBoundingClientRect().width;
              const what = `${select.id}: "${option.text}" ${needed} > ${has}`;
              return needed > has + 0.5 ? what : null;
            })).filter(Boolean)"""
    )
    assert clipped == []
    assert page.evaluate("() => document.documentElement.scrollWidth") <= width


def test_stop_all_stays_on_one_line_and_on_screen(sized: tuple[Any, int]) -> None:
    page, width = sized
    lines, right = page.evaluate(
        """() => {
            const button = document.getElementById('stop');
            const text = [...button.childNodes]
              .find((n) => n.nodeType === 3 && n.textContent.trim());
            const range = document.createRange();
            range.selectNodeContents(text);
            const tops = new Set([...range.getClientRects()].map((r) => Math.round(r.top)));
            return [tops.size, button.getBoundingClientRect().right];
        }"""
    )
    assert lines == 1, '"Stop all" wraps'
    assert right <= width
    screenshot(page, f"topbar_{width}")


def test_axis_labels_are_readable(sized: tuple[Any, int]) -> None:
    page, width = sized
    labels = page.evaluate(
        """() => {
            const svg = document.getElementById('armband').getBoundingClientRect();
            return [...document.querySelectorAll('#armband .axes text')].map((t) => {
              const r = t.getBoundingClientRect();
              return {text: t.textContent, height: r.height,
                      inside: r.left >= svg.left - 0.5 && r.right <= svg.right + 0.5
                              && r.top >= svg.top - 0.5 && r.bottom <= svg.bottom + 0.5};
            });
        }"""
    )
    assert len(labels) >= 6
    small = [
        (label["text"], round(label["height"], 1))
        for label in labels
        if label["height"] < MIN_LABEL_PX
    ]
    assert small == []
    assert [label["text"] for label in labels if not label["inside"]] == [], "cut off at the edge"
    screenshot(page, f"armband_{width}")


def test_a_refused_save_says_so_and_keeps_the_drawn_path(
    sized: tuple[Any, int], armband: ArmbandOnPage, console: ConsoleErrors
) -> None:
    page, width = sized
    console.allow(r"Failed to load resource: the server responded with a status of 4\d\d")
    page.click("#draw-path")
    page.mouse.move(*armband.point(1.9, 12.0))
    page.mouse.down()
    for i in range(1, 11):
        page.mouse.move(*armband.point(1.9, 12.0 - i))
    page.mouse.up()
    page.wait_for_function("() => document.getElementById('source').value === 'drawn'")
    page.fill("#save-name", f"fit-test-{width}")
    page.click("#save")
    page.wait_for_function("() => document.getElementById('job').textContent.startsWith('Saved')")
    # Over the speed limit (1000 cm/s): the plan and the save are refused.
    page.fill("#speed", "5000")
    page.wait_for_function("() => document.getElementById('plan-error').textContent !== ''")
    page.click("#save")
    page.wait_for_function(
        "() => document.getElementById('job').textContent.startsWith('Not saved')"
    )
    assert page.locator("#alerts [role=alert]").first.inner_text()
    # The drawn stroke, from y = 12 cm to 2 cm along x = 1.9 cm (the SVG's x is the arm's y).
    points = (page.get_attribute("#armband polyline.plan-path", "points") or "").split()
    assert points, "the drawn path is still on the armband"
    first, last = (tuple(float(v) for v in p.split(",")) for p in (points[0], points[-1]))
    assert first == pytest.approx((12.0, 1.9), abs=0.3)
    assert last == pytest.approx((2.0, 1.9), abs=0.3)
    screenshot(page, f"refused_save_{width}")
