"""The page's .tact panel: a bHaptics Designer file chosen or dropped is stored in the
library under its stem and summarised; Play plays it on the armband; a file with nothing
for an arm is refused in one line and nothing is stored."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx

from tests.web.support import ConsoleErrors, StateObserver, screenshot, wait_until

CORPUS = Path(__file__).parents[1] / "clips" / "samples" / "tact" / "bhaptics-popone-support"
ARM_FILE = CORPUS / "Arm" / "RubbingDefib.tact"
VEST_FILE = CORPUS / "Vest" / "ActiveBuff.tact"
ARMS = {"ForearmL", "ForearmR"}
LIST_LIMIT = 20
"""How many stored projects the panel lists (the first page of GET /tact)."""
REFUSED = r"Failed to load resource: the server responded with a status of 422"


def file_facts(path: Path) -> tuple[float, list[str], int]:
    """Length (s), arm positions and number of effects, read from the file itself: an
    effect lasts offsetTime ms from its startTime (docs/bhaptics.md)."""
    project = json.loads(path.read_text(encoding="utf-8-sig"))["project"]
    effects = [e for track in project["tracks"] for e in track["effects"]]
    arm = [e for e in effects if ARMS & set(e["modes"])]
    end_ms = max(float(e["startTime"]) + float(e["offsetTime"]) for e in arm)
    positions = sorted(ARMS & {p for e in arm for p in e["modes"]})
    return end_ms / 1000.0, positions, len(effects)


def drop_file(page: Any, path: Path, name: str) -> None:
    """Drop the file's bytes, named `name`, on the panel's drop zone as a browser would."""
    transfer = page.evaluate_handle(
        """([bytes, name]) => {
            const transfer = new DataTransfer();
            transfer.items.add(new File([new Uint8Array(bytes)], name));
            return transfer;
        }""",
        [list(path.read_bytes()), name],
    )
    for kind in ("dragenter", "dragover", "drop"):
        page.dispatch_event("#tact-drop", kind, {"dataTransfer": transfer})


def summary_shown(page: Any) -> dict[str, str]:
    return dict(
        page.evaluate(
            """() => [...document.querySelectorAll('#tact-summary dd[data-key]')]
                .map((dd) => [dd.dataset.key, dd.textContent])"""
        )
    )


def page_levels(page: Any) -> list[float]:
    return [
        float(v)
        for v in page.evaluate(
            """() => [...document.querySelectorAll('#armband [data-actuator]')]
                .map((g) => g.dataset.level || '0')"""
        )
    ]


def test_a_chosen_arm_file_is_stored_summarised_and_played(
    page: Any, server: str, observer: StateObserver
) -> None:
    httpx.delete(f"{server}/tact/my_defib__1_")
    duration_s, positions, effects = file_facts(ARM_FILE)
    # A file name outside the name rule is made one: each other character becomes "_".
    page.set_input_files(
        "#tact-file",
        {"name": "my defib (1).tact", "mimeType": "", "buffer": ARM_FILE.read_bytes()},
    )
    page.wait_for_selector("#tact-loaded:not([hidden])")
    assert page.inner_text("#tact-name") == "my_defib__1_"
    assert summary_shown(page) == {
        "duration_s": f"{duration_s:.2f} s",
        "positions": ", ".join(positions),
        "effects": str(effects),
    }
    stored = httpx.get(f"{server}/tact/my_defib__1_")
    assert stored.status_code == 200
    assert stored.json()["project"]["tracks"][0]["effects"][0]["startTime"] == 0
    page.wait_for_selector('#tact-list li[data-name="my_defib__1_"]')

    observer.wait_for(lambda s: max(s["levels"], default=0.0) == 0.0, what="silence first")
    start = observer.mark()
    page.click("#tact-play")
    observer.wait_for(
        lambda s: s["active_voices"] >= 1 and max(s["levels"]) > 0,
        since=start,
        what="the project playing",
    )
    # "See": the page's armband shows the live levels as it plays.
    wait_until(page, lambda: max(page_levels(page)) > 0)
    page.wait_for_function(
        "() => document.getElementById('tact-message').textContent"
        ".startsWith('Playing my_defib__1_: 1.00 s, 6 voices')"
    )
    screenshot(page, "tact_playing")
    observer.wait_for(
        lambda s: s["active_voices"] == 0, since=start, timeout_s=10.0, what="the end"
    )
    httpx.delete(f"{server}/tact/my_defib__1_").raise_for_status()


def test_a_dropped_arm_file_plays_from_the_list(
    page: Any, server: str, observer: StateObserver
) -> None:
    httpx.delete(f"{server}/tact/RubbingDefib")
    drop_file(page, ARM_FILE, ARM_FILE.name)
    page.wait_for_selector('#tact-list li[data-name="RubbingDefib"]')
    assert httpx.get(f"{server}/tact/RubbingDefib").status_code == 200
    assert page.inner_text("#tact-message") == "Stored RubbingDefib.tact as RubbingDefib."
    listed = {e["name"]: e for e in httpx.get(f"{server}/tact?limit=1000").json()}
    assert "RubbingDefib" in listed
    start = observer.mark()
    page.click('#tact-list li[data-name="RubbingDefib"] button')
    observer.wait_for(
        lambda s: s["active_voices"] >= 1 and max(s["levels"]) > 0,
        since=start,
        what="the listed project playing",
    )
    httpx.delete(f"{server}/tact/RubbingDefib").raise_for_status()


def test_a_vest_file_is_refused_in_one_line_and_not_stored(
    page: Any, server: str, console: ConsoleErrors
) -> None:
    console.allow(REFUSED)
    refusal = httpx.put(
        f"{server}/tact/probe",
        content=VEST_FILE.read_bytes(),
        headers={"Content-Type": "application/json"},
    )
    assert refusal.status_code == 422
    message = refusal.json()["error"]["message"]
    drop_file(page, VEST_FILE, VEST_FILE.name)
    page.wait_for_function(
        "() => document.getElementById('tact-message').dataset.state === 'error'"
    )
    line = page.inner_text("#tact-message")
    assert line == f"{VEST_FILE.name} not stored: {message}"
    assert "\n" not in line
    assert "arm" in line.lower()
    assert page.is_hidden("#tact-loaded")
    assert httpx.get(f"{server}/tact/ActiveBuff").status_code == 404
    assert page.locator('#tact-list li[data-name="ActiveBuff"]').count() == 0
    screenshot(page, "tact_refused")


def test_a_file_that_is_not_json_is_refused_in_one_line(
    page: Any, server: str, console: ConsoleErrors
) -> None:
    console.allow(REFUSED)
    page.set_input_files(
        "#tact-file", {"name": "broken.tact", "mimeType": "", "buffer": b'{"project": ['}
    )
    page.wait_for_function(
        "() => document.getElementById('tact-message').dataset.state === 'error'"
    )
    line = page.inner_text("#tact-message")
    assert line.startswith("broken.tact not stored: ")
    assert "\n" not in line
    assert httpx.get(f"{server}/tact/broken").status_code == 404


def test_the_list_shows_the_first_page_only(page: Any, server: str) -> None:
    tap = {
        "project": {
            "tracks": [
                {
                    "effects": [
                        {
                            "startTime": 0,
                            "offsetTime": 300,
                            "modes": {
                                "ForearmL": {
                                    "mode": "DOT_MODE",
                                    "dotMode": {
                                        "feedback": [
                                            {
                                                "startTime": 0,
                                                "endTime": 300,
                                                "playbackType": "NONE",
                                                "pointList": [{"index": 1, "intensity": 1}],
                                            }
                                        ]
                                    },
                                }
                            },
                        }
                    ]
                }
            ]
        }
    }
    names = [f"web-tap-{i:02d}" for i in range(LIST_LIMIT + 1)]
    for name in names:
        httpx.put(f"{server}/tact/{name}", json=tap).raise_for_status()
    try:
        page.click("#tact-refresh")
        page.wait_for_selector("#tact-more:not([hidden])")
        first_page = [e["name"] for e in httpx.get(f"{server}/tact?limit={LIST_LIMIT}").json()]
        shown = page.eval_on_selector_all(
            "#tact-list li", "items => items.map(i => i.dataset.name)"
        )
        assert shown == first_page
        assert len(shown) == LIST_LIMIT
        assert f"first {LIST_LIMIT}" in page.inner_text("#tact-more")
        assert page.inner_text('#tact-list li[data-name="web-tap-00"] span') == (
            "0.30 s · ForearmL · 1 effect"
        )
    finally:
        for name in names:
            httpx.delete(f"{server}/tact/{name}")
