"""The page's bHaptics games panel: a game's deployment chosen is stored in the workspace
library for the id typed beside it (or the file's own workspaceId) and listed with its
events; a refused deployment says why in one line, naming the field; Remove removes it."""

from __future__ import annotations

import json
from typing import Any

import httpx

from tests.support.deployments import BOTH, VEST_CLIP, mapping, portal
from tests.web.support import ConsoleErrors, screenshot

REFUSED = r"Failed to load resource: the server responded with a status of 422"


def choose(page: Any, name: str, document: Any) -> None:
    page.set_input_files(
        "#games-file",
        {"name": name, "mimeType": "", "buffer": json.dumps(document).encode("utf-8")},
    )


def test_a_chosen_deployment_is_stored_for_its_own_workspace_and_listed(
    page: Any, server: str
) -> None:
    httpx.delete(f"{server}/bhaptics/workspaces/ws-123")
    choose(page, "default-config.json", BOTH)
    page.wait_for_selector('#games-list li[data-workspace="ws-123"]')
    assert page.inner_text("#games-message") == (
        "Stored default-config.json for workspace ws-123: A Game · 3 events, 3 on an arm · "
        "longest 274 ms."
    )
    stored = httpx.get(f"{server}/bhaptics/workspaces/ws-123")
    assert stored.status_code == 200 and stored.json() == BOTH
    row = page.inner_text('#games-list li[data-workspace="ws-123"]')
    assert "A Game · 3 events, 3 on an arm" in row
    screenshot(page, "games_listed")
    page.click('#games-list li[data-workspace="ws-123"] button')
    page.wait_for_selector('#games-list li[data-workspace="ws-123"]', state="detached")
    assert httpx.get(f"{server}/bhaptics/workspaces/ws-123").status_code == 404


def test_the_typed_id_decides_and_a_nameless_file_asks_for_one(page: Any, server: str) -> None:
    nameless = {"hapticMappings": [mapping("vest", clips=[VEST_CLIP])]}
    choose(page, "nameless.json", nameless)
    page.wait_for_function(
        "() => document.getElementById('games-message').dataset.state === 'error'"
    )
    assert "names no workspaceId" in page.inner_text("#games-message")
    page.fill("#games-workspace", "typed-id")
    choose(page, "nameless.json", nameless)
    page.wait_for_selector('#games-list li[data-workspace="typed-id"]')
    assert "0 on an arm" in page.inner_text('#games-list li[data-workspace="typed-id"]')
    httpx.delete(f"{server}/bhaptics/workspaces/typed-id").raise_for_status()


def test_a_refused_deployment_says_why_in_one_line(
    page: Any, server: str, console: ConsoleErrors
) -> None:
    console.allow(REFUSED)
    bad = portal(mapping("a"), mapping("b", intensity=300), workspace="bad-game")
    refusal = httpx.put(f"{server}/bhaptics/workspaces/bad-game", json=bad)
    assert refusal.status_code == 422
    message = refusal.json()["error"]["message"]
    assert "message.hapticMappings[1].intensity=300" in message
    choose(page, "bad.json", bad)
    page.wait_for_function(
        "() => document.getElementById('games-message').dataset.state === 'error'"
    )
    line = page.inner_text("#games-message")
    assert line == f"bad.json not stored: {message}"
    assert "\n" not in line
    assert httpx.get(f"{server}/bhaptics/workspaces/bad-game").status_code == 404
