"""Attacks on the output stage (issue 34, item 4, and wearer switching), bounded in count
and time, loopback only; each meant to run in a process of its own
(:func:`tests.support.abuse.in_process`) beside another client's touch
(:func:`tests.support.fairness.victim_touch`).

Each returns what the server answered and, read from ``/metrics`` afterwards, the blocks
muted for NaN (another client's touch silent) and the voices silenced alone;
:func:`voices_on` tells, once every touch asked for is over, whether a vibration stayed on.
"""

from __future__ import annotations

import re
import time
from typing import Any

import httpx

STILL: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 7.0]]},
    "duration_s": 2.0,
    "fade_in_s": 0.05,
    "fade_out_s": 0.05,
}


def _metric(text: str, name: str) -> float:
    match = re.search(rf"^{name} (\S+)$", text, re.MULTILINE)
    return float(match.group(1)) if match else float("nan")


def _after(client: httpx.Client, answers: dict[str, Any]) -> dict[str, Any]:
    """``answers`` with what ``/metrics`` shows once the touches are over."""
    time.sleep(2.5)  # the 2 s touches end
    text = client.get("/metrics").text
    return {
        **answers,
        "muted_blocks": _metric(text, "phantomtouch_muted_blocks_total"),
        "silenced": _metric(text, 'phantomtouch_silenced_voices_total{reason="non_finite"}'),
    }


def voices_on(url: str) -> float:
    """Voices sounding now (``/metrics``): 0 once every touch asked for is over."""
    return _metric(httpx.get(f"{url}/metrics", timeout=10).text, "phantomtouch_active_voices")


def _clip(**data: Any) -> dict[str, Any]:
    clip = {"duration_s": 0.5, "amplitude": [{"t_s": 0.0, "value": 1.0}], **data}
    return {**STILL, "carrier": {"kind": "clip", "loop": True, "data": clip}}


def nan_clip(url: str) -> dict[str, Any]:
    """A looped clip of ``duration_s`` 5e-324 (rendered NaN before the edge refused it)."""
    with httpx.Client(base_url=url, timeout=30) as client:
        answer = client.post("/touch", json=_clip(duration_s=5e-324))
        return _after(client, {"answer": answer.status_code})


def many_transients(url: str) -> dict[str, Any]:
    """20,000 transients at t = 0 (refused), then the 1000 the edge allows (played)."""
    click = {"t_s": 0.0, "amplitude": 0.001, "frequency": 0.0}
    with httpx.Client(base_url=url, timeout=30) as client:
        many = client.post("/touch", json=_clip(transients=[click] * 20_000)).status_code
        allowed = client.post("/touch", json=_clip(transients=[click] * 1000)).status_code
        return _after(client, {"answer": many, "1000": allowed})


def sub_band_sine(url: str) -> dict[str, Any]:
    """A sine at 0.01 Hz at full intensity (near full scale for seconds before)."""
    touch = {**STILL, "carrier": {"kind": "sine", "freq_hz": 0.01}, "intensity": 1.0}
    with httpx.Client(base_url=url, timeout=30) as client:
        answer = client.post("/touch", json=touch)
        return _after(client, {"answer": answer.status_code})


def planned_past_quota(url: str) -> dict[str, Any]:
    """A client holding its voice-second quota (quiet 1 h touches until refused) posts a
    1 h touch of 80,000 points, as long as the one refused: the answer and the time it
    takes (it used to be planned before the quota was checked)."""
    with httpx.Client(base_url=url, timeout=60) as client:
        held = 0
        quiet = {**STILL, "duration_s": 3600.0, "intensity": 0.01}
        for _ in range(200):  # until the quota answers (a busy engine's 503 is tried again)
            code = client.post("/touch", json=quiet).status_code
            if code == 429:
                break
            held += code == 202
        points = [[1, 2 + 9 * (k % 2)] for k in range(80_000)]
        big = {**STILL, "path": {"kind": "polyline", "points_cm": points}, "duration_s": 3600.0}
        began = time.perf_counter()
        answer = client.post("/touch", json=big)
        took_ms = (time.perf_counter() - began) * 1e3
        client.post("/stop")
        return _after(
            client, {"held": held, "answer": answer.status_code, "took_ms": round(took_ms)}
        )


def wearer_switches(url: str, seconds: float = 3.0) -> dict[str, Any]:
    """``PUT /wearer`` between two profiles (+20 dB and -20 dB) as fast as one client can."""
    with httpx.Client(base_url=url, timeout=10) as client:
        for name, offset_db in (("loud", 20.0), ("soft", -20.0)):
            client.put(f"/wearers/{name}", json={"offsets_db": {"sine_100hz": {"1": offset_db}}})
        counts: dict[str, int] = {}
        end = time.monotonic() + seconds
        k = 0
        while time.monotonic() < end:
            k += 1
            code = client.put("/wearer", json={"name": "loud" if k % 2 else "soft"}).status_code
            counts[str(code)] = counts.get(str(code), 0) + 1
        client.delete("/wearer")
        return _after(client, {"answers": counts})
