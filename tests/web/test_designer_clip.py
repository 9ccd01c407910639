"""The designer takes a haptic clip of the library as a stroke's carrier."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx

from phantomtouch.clips import load_clip
from tests.web.support import StateObserver, screenshot
from tests.web.test_designer import select_preset, server_plan, wait_for_plan

SAMPLES = Path(__file__).parents[1] / "clips" / "samples"


def test_a_designed_stroke_plays_a_clip_as_its_carrier(
    page: Any, server: str, observer: StateObserver
) -> None:
    clip = json.loads(load_clip(SAMPLES / "swell.haptic").model_dump_json())
    httpx.put(f"{server}/clips/web-swell", json=clip).raise_for_status()
    page.click("#refresh-library")
    page.wait_for_selector("#carrier-clip option[value=web-swell]", state="attached")
    select_preset(page, "exp2/central")
    assert page.is_disabled("#carrier-clip")
    page.select_option("#carrier", "clip")
    assert not page.is_disabled("#carrier-clip")
    assert page.is_disabled("#carrier-freq")
    page.select_option("#carrier-clip", "web-swell")
    expected = server_plan(
        server,
        {
            "preset": "exp2/central",
            "overrides": {"carrier": {"kind": "clip", "clip": "web-swell"}},
        },
    )
    wait_for_plan(page, expected)
    # The clip is a sine under its envelope: the 100 Hz sine's Table I level.
    assert float(page.get_attribute("#plan dd[data-key=level_db]", "data-value")) == 128

    start = observer.mark()
    page.click("#play")
    observer.wait_for(
        lambda s: s["active_voices"] >= 1 and max(s["levels"]) > 0,
        since=start,
        what="the stroke with the clip playing",
    )
    screenshot(page, "designer_clip_carrier")
    httpx.post(f"{server}/stop").raise_for_status()
    httpx.delete(f"{server}/clips/web-swell").raise_for_status()
