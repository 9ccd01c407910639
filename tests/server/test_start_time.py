"""A touch's start time is one value: ``start_at_s`` in the answer to ``POST /touch`` is
the ``start_at_s`` that ``GET /jobs/{id}`` gives for the same start frame, however far the
engine's clock has moved on meanwhile (its mapping of frames to server time tracks the
sound card, and moves by a few ms on a loaded machine)."""

from __future__ import annotations

import time

import httpx

from tests.support.live_server import LiveServer


def test_the_answer_and_the_job_give_the_same_start_time(live: LiveServer) -> None:
    began = time.monotonic()
    assert httpx.post(f"{live.url}/touch", json={"preset": "vr/tap"}, timeout=30.0).is_success
    # 100 ms ahead on a quiet machine, and ten times as long as a plain touch took on a
    # busy one: each reaches the engine before its start frame.
    lead_ms = 100.0 + 10 * (time.monotonic() - began) * 1e3
    answers = []
    for _ in range(5):
        touch = httpx.post(
            f"{live.url}/touch", json={"preset": "vr/tap", "start_in_ms": lead_ms}, timeout=30.0
        )
        assert touch.status_code == 202, touch.text
        answers.append(touch.json())
        time.sleep(0.05)
    deadline = time.monotonic() + 60.0
    compared = 0
    for answer in answers:
        while (job := httpx.get(f"{live.url}/jobs/{answer['job_id']}").json())["state"] != (
            "finished"
        ):
            assert time.monotonic() < deadline, job
            time.sleep(0.05)
        assert not job["late"], job  # ahead: each started at its frame
        assert job["start_frame"] == answer["start_frame"]
        assert job["start_at_s"] == answer["start_at_s"], (job, answer)
        compared += 1
    assert compared == len(answers)
