"""``GET /clips`` and ``GET /wearers`` a page at a time, against a real server process.

Twenty clips of about 1 MB each are stored; listing them reads their sizes without
loading one: the server's peak memory (``VmHWM``) grows by less than one loaded clip's
worth, and the page's sizes are those of the stored clips. Pages follow ``limit`` and
``offset``, and a page size out of range is a 422 naming the field.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.live_server import LiveServer

CLIPS = 20
POINTS = 14_000
"""Breakpoints per envelope: some 0.9 MB of JSON per clip."""


def big_clip(index: int) -> dict[str, Any]:
    times = [round(i * 0.01, 2) for i in range(POINTS)]
    return {
        "duration_s": POINTS * 0.01,
        "amplitude": [{"t_s": t, "value": 0.5} for t in times],
        "frequency": [{"t_s": t, "value": 0.25} for t in times],
        "transients": [{"t_s": 1.0, "amplitude": 1.0, "frequency": 0.5}] * (index + 1),
    }


def peak_rss_bytes(pid: int) -> int:
    status = Path(f"/proc/{pid}/status").read_text()
    match = re.search(r"^VmHWM:\s+(\d+) kB$", status, re.MULTILINE)
    assert match is not None
    return int(match.group(1)) * 1024


@pytest.fixture(scope="module")
def stocked(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("pages")
    env = {"XDG_RUNTIME_DIR": str(folder)}
    with (
        LiveServer(folder / "p.db", env=env) as server,
        httpx.Client(base_url=server.url, timeout=60) as client,
    ):
        for index in range(CLIPS):
            stored = client.put(f"/clips/clip-{index:02d}", json=big_clip(index))
            assert stored.status_code in (200, 201), stored.text
        for index in range(5):
            profile = {"offsets_db": {"sine_100hz": {"1": float(index)}}}
            assert client.put(f"/wearers/w-{index}", json=profile).status_code in (200, 201)
    # a fresh process, whose peak memory is not that of the uploads
    with LiveServer(folder / "p.db", env=env) as server:
        yield server


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_listing_large_clips_loads_none(stocked: LiveServer) -> None:
    assert stocked.process is not None
    with httpx.Client(base_url=stocked.url, timeout=60) as client:
        client.get("/wearers", params={"limit": 1})  # the code a listing runs is warm
        client.get("/clips/none")
        before = peak_rss_bytes(stocked.process.pid)
        listed = client.get("/clips", params={"limit": 1000}).json()
        grown = peak_rss_bytes(stocked.process.pid) - before
    assert [c["name"] for c in listed] == [f"clip-{i:02d}" for i in range(CLIPS)]
    assert all(c["amplitude_points"] == POINTS and c["frequency_points"] == POINTS for c in listed)
    assert [c["transients"] for c in listed] == list(range(1, CLIPS + 1))
    assert all(c["duration_s"] == pytest.approx(POINTS * 0.01) for c in listed)
    # one clip loaded costs more than this (its 28,000 breakpoints as objects)
    assert grown < 8 << 20, f"peak memory grew by {grown / 2**20:.0f} MB"


def test_pages_follow_limit_and_offset(stocked: LiveServer) -> None:
    with httpx.Client(base_url=stocked.url, timeout=60) as client:
        page = client.get("/clips", params={"limit": 7, "offset": 14}).json()
        assert [c["name"] for c in page] == [f"clip-{i:02d}" for i in range(14, 20)]
        assert client.get("/clips", params={"offset": 20}).json() == []
        first = client.get("/clips").json()
        assert len(first) == CLIPS  # the default page (100) holds them all
        wearers = client.get("/wearers", params={"limit": 2, "offset": 3}).json()
        assert [w["name"] for w in wearers] == ["w-3", "w-4"]
        refused = client.get("/wearers", params={"limit": 0})
        assert refused.status_code == 422
        assert refused.json()["error"]["fields"][0]["field"] == "limit"
        schema = client.get("/openapi.json").json()
        for path in ("/clips", "/wearers"):
            names = {p["name"] for p in schema["paths"][path]["get"]["parameters"]}
            assert names == {"limit", "offset"}
