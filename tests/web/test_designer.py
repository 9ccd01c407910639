"""The pattern designer: a preset's plan and gain chart, playing, drawing, saving, WAV."""

from __future__ import annotations

import math
from typing import Any

import httpx
import pytest
import soundfile

from tests.web.support import ArmbandOnPage, ConsoleErrors, StateObserver, screenshot

PLAN_KEYS = ("duration_s", "path_length_cm", "speed_cm_s", "frames")


def wait_for_plan(page: Any, expected: dict[str, Any]) -> None:
    """Wait until the page shows the plan numbers of `expected` (the designer replans)."""
    page.wait_for_function(
        """expected => Object.entries(expected).every(([key, value]) => {
            const dd = document.querySelector(`#plan dd[data-key=${key}]`);
            return dd && Number(dd.dataset.value) === value;
        })""",
        arg={key: expected[key] for key in PLAN_KEYS},
    )


def shown_plan(page: Any) -> dict[str, float]:
    """The plan numbers the page shows (their exact values, from data-value)."""
    page.wait_for_selector("#plan dd[data-key=duration_s][data-value]")
    return {
        key: float(page.get_attribute(f"#plan dd[data-key={key}]", "data-value"))
        for key in PLAN_KEYS
    }


def server_plan(server: str, touch_request: dict[str, Any]) -> dict[str, Any]:
    response = httpx.post(
        f"{server}/render", json=touch_request, headers={"Accept": "application/json"}
    )
    response.raise_for_status()
    return dict(response.json())


def coloured_pixels(page: Any) -> int:
    """Pixels of the chart in a channel colour (the slate greys of grid and text are not)."""
    return int(
        page.evaluate(
            """() => {
                const c = document.getElementById("chart");
                const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
                let n = 0;
                for (let i = 0; i < d.length; i += 4) {
                    const hi = Math.max(d[i], d[i + 1], d[i + 2]);
                    const lo = Math.min(d[i], d[i + 1], d[i + 2]);
                    if (d[i + 3] > 128 && hi - lo > 80) n += 1;
                }
                return n;
            }"""
        )
    )


def select_preset(page: Any, name: str) -> None:
    page.select_option("#source", f"preset:{name}")
    page.wait_for_function(
        "name => document.querySelector('#source-summary').textContent !== ''"
        " && document.getElementById('source').value === 'preset:' + name",
        arg=name,
    )


def test_preset_plan_matches_the_server_and_the_chart_is_drawn(
    page: Any, server: str, observer: StateObserver
) -> None:
    select_preset(page, "exp2/curved")
    expected = server_plan(server, {"preset": "exp2/curved"})
    wait_for_plan(page, expected)
    assert page.inner_text("#plan dd[data-key=duration_s]") == f"{expected['duration_s']:.3f} s"
    assert page.inner_text("#plan dd[data-key=path_length_cm]") == (
        f"{expected['path_length_cm']:.2f} cm"
    )
    assert page.inner_text("#plan dd[data-key=speed_cm_s]") == f"{expected['speed_cm_s']:.2f} cm/s"
    # Eight lanes of curves: far more coloured pixels than the eight lane labels alone.
    assert coloured_pixels(page) > 3000
    description = page.get_attribute("#chart", "aria-label") or ""
    assert "8 actuators" in description and f"{expected['duration_s']:.2f} s" in description
    path_points = page.get_attribute("#armband .plan-path", "points") or ""
    assert len(path_points.split()) > 10, "the arc is drawn on the armband"

    start = observer.mark()
    page.click("#play")
    playing = observer.wait_for(
        lambda s: s["active_voices"] >= 1 and max(s["levels"]) > 0,
        since=start,
        what="the preset playing",
    )
    assert playing["contacts"] == []
    page.wait_for_function("() => document.getElementById('job').textContent.includes('Playing')")
    page.wait_for_timeout(1200)
    screenshot(page, "preset_playing")
    observer.wait_for(
        lambda s: s["active_voices"] == 0,
        since=start,
        timeout_s=expected["duration_s"] + 5,
        what="the preset finished",
    )


def test_designer_settings_reach_the_plan(page: Any, server: str) -> None:
    select_preset(page, "exp2/central")
    page.fill("#speed", "4")
    page.select_option("#modulation", "stroke")
    page.select_option("#intensity", "high")
    expected = server_plan(
        server,
        {
            "preset": "exp2/central",
            "overrides": {
                "speed_cm_s": 4,
                "modulation": {"index": 1, "freq_hz": "stroke"},
                "intensity": "high",
            },
        },
    )
    wait_for_plan(page, expected)
    assert expected["speed_cm_s"] == 4
    # eq. 1: fades plus length / speed.
    assert expected["duration_s"] == pytest.approx(0.6 + expected["path_length_cm"] / 4 + 0.6)
    # Table I, high, 100 Hz.
    assert float(page.get_attribute("#plan dd[data-key=level_db]", "data-value")) == 138


def test_draw_a_path_save_it_and_download_its_wav(
    page: Any, server: str, armband: ArmbandOnPage, tmp_path: Any
) -> None:
    page.click("#draw-path")
    assert page.get_attribute("#armband", "data-mode") == "draw"
    start = armband.point(1.9, 13.0)
    end = armband.point(1.9, 1.0)
    page.mouse.move(*start)
    page.mouse.down()
    for i in range(1, 31):
        f = i / 30
        # A gentle S-curve along the forearm.
        page.mouse.move(*armband.point(1.9 + 1.2 * math.sin(f * 2 * math.pi), 13.0 - 12.0 * f))
    page.mouse.move(*end)
    page.mouse.up()
    page.wait_for_function("() => document.getElementById('source').value === 'drawn'")
    page.fill("#speed", "8")
    page.wait_for_function(
        "() => document.querySelector('#plan dd[data-key=speed_cm_s]').dataset.value === '8'"
    )
    shown = shown_plan(page)
    assert shown["path_length_cm"] > 12.0, "the S-curve is longer than the straight line"
    screenshot(page, "drawn_path")

    page.fill("#save-name", "web-test-stroke")
    page.click("#save")
    page.wait_for_selector("#library li:has-text('web-test-stroke')")
    stored = httpx.get(f"{server}/patterns/web-test-stroke").json()
    assert stored["speed_cm_s"] == 8
    assert stored["path"]["kind"] == "polyline"
    assert len(stored["path"]["points_cm"]) >= 3
    names = [p["name"] for p in httpx.get(f"{server}/patterns").json()]
    assert "web-test-stroke" in names

    with page.expect_download() as download_info:
        page.click("#download")
    target = tmp_path / "drawn.wav"
    download_info.value.save_as(target)
    info = soundfile.info(str(target))
    device = httpx.get(f"{server}/device").json()
    assert info.channels == len(device["actuators"])
    assert info.subtype == "FLOAT"
    assert info.frames == int(shown["frames"])

    page.select_option("#source", "saved:web-test-stroke")
    page.wait_for_function(
        "() => document.querySelector('#plan dd[data-key=speed_cm_s]').dataset.value === '8'"
    )


def test_a_refused_request_shows_the_server_message(
    page: Any, server: str, console: ConsoleErrors
) -> None:
    # Chromium logs every 4xx answer to the console; those are the point of this test.
    console.allow(r"Failed to load resource: the server responded with a status of 4\d\d")
    select_preset(page, "exp2/central")
    page.fill("#speed", "0")
    alert = page.locator("#plan-error[role=alert]")
    alert.wait_for()
    page.wait_for_function("() => document.getElementById('plan-error').textContent !== ''")
    assert "speed_cm_s" in alert.inner_text()
    page.click("#play")
    toast = page.locator("#alerts [role=alert]").first
    toast.wait_for()
    refused = httpx.post(
        f"{server}/touch",
        json={"preset": "exp2/central", "overrides": {"speed_cm_s": 0}},
    )
    assert refused.status_code in (400, 422)
    assert refused.json()["error"]["message"] in toast.inner_text()
    screenshot(page, "error_shown")
    page.click("#alerts [role=alert] button")
    assert page.locator("#alerts [role=alert]").count() == 0


def test_library_edit_save_play_and_delete(page: Any, server: str, observer: StateObserver) -> None:
    stored = {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.0]]},
        "duration_s": 3.0,
        "modulation": {"index": 1.0},
        "level_db": 130.0,
    }
    assert httpx.put(f"{server}/patterns/web-test-library", json=stored).status_code == 200
    page.fill("#speed", "9")  # a setting left over from before is reset by Edit
    page.click("#refresh-library")
    item = page.locator("#library li", has_text="web-test-library")
    item.get_by_role("button", name="Edit web-test-library in the designer").click()
    wait_for_plan(page, server_plan(server, {"stored": "web-test-library"}))
    assert page.input_value("#speed") == ""

    page.fill("#speed", "6")
    page.select_option("#modulation", "none")
    page.wait_for_function(
        "() => document.querySelector('#plan dd[data-key=speed_cm_s]').dataset.value === '6'"
    )
    assert page.input_value("#save-name") == "web-test-library"
    page.click("#save")
    page.wait_for_function("() => document.getElementById('job').textContent.startsWith('Saved')")
    saved = httpx.get(f"{server}/patterns/web-test-library").json()
    assert saved["speed_cm_s"] == 6
    assert "duration_s" not in saved and "modulation" not in saved
    assert saved["level_db"] == 130

    start = observer.mark()
    item.get_by_role("button", name="Play web-test-library").click()
    observer.wait_for(lambda s: s["active_voices"] >= 1, since=start, what="the saved pattern")

    page.once("dialog", lambda dialog: dialog.accept())
    item.get_by_role("button", name="Delete web-test-library").click()
    item.wait_for(state="detached")
    assert httpx.get(f"{server}/patterns/web-test-library").status_code == 404
    assert page.input_value("#source").startswith("preset:exp2/")
