"""Every REST route of the Python client (sdk_clients/python) against the real service.

The calls go to a ``phantomtouch serve`` subprocess; what the server did is checked from
its side (job state, the stored patterns, clips and wearers). The refusals and retries are
in test_client_python_errors.py.
"""

from __future__ import annotations

import asyncio
import io

import numpy as np
import pytest
import soundfile
from phantomtouch_client import (
    AsyncClient,
    Client,
    InvalidRequest,
    Job,
    NotFound,
    TouchPattern,
)

from tests.clients.live import wait_until
from tests.clients.python_client import JOB_STATES, STROKE
from tests.support.live_server import LiveServer


def test_health_clock_device_presets(client: Client) -> None:
    assert client.health().status == "ok"
    first = client.clock()
    second = client.clock()
    assert second.server_time_s >= first.server_time_s
    assert first.sample_rate_hz > 0
    device = client.device()
    assert device.model_dump(exclude_none=True)
    names = {p.name for p in client.presets()}
    assert "exp2/curved" in names


def test_touch_with_preset_then_job_and_cancel(client: Client) -> None:
    job = client.touch(preset="exp2/curved", start_in_ms=50)
    assert job.duration_s > 0
    status = client.job(job.job_id)
    assert status.job_id == job.job_id
    assert status.state in JOB_STATES
    cancelled = client.cancel_job(job.job_id)
    assert cancelled.state in {"stopped", "finished"}


def test_touch_with_pattern_at_a_server_time(client: Client) -> None:
    start_at_s = client.clock().server_time_s + 0.2
    job = client.touch(STROKE, start_at_s=start_at_s)
    assert job.start_at_s == pytest.approx(start_at_s, abs=0.05)
    # Path 9.6 cm at 20 cm/s plus the fades (eq. 1).
    assert job.duration_s == pytest.approx(0.05 + 9.6 / 20.0 + 0.05, rel=1e-3)
    assert job.path_length_cm == pytest.approx(9.6, rel=1e-6)


def test_render_answers_an_eight_channel_float_wav(client: Client) -> None:
    wav = client.render(STROKE)
    samples, rate_hz = soundfile.read(io.BytesIO(wav), dtype="float32", always_2d=True)
    assert samples.shape[1] == 8
    assert samples.shape[0] == pytest.approx(0.58 * rate_hz, abs=2)
    assert soundfile.info(io.BytesIO(wav)).subtype == "FLOAT"
    assert np.isfinite(samples).all()


def test_render_plan_answers_curves(client: Client) -> None:
    plan = client.render_plan(preset="exp2/curved")
    curves = plan.curves
    assert 0 < len(curves.times_s) <= 500
    assert len(curves.positions_cm) == len(curves.times_s) == len(curves.gains)
    assert all(len(g) == 8 for g in curves.gains)


def test_patterns_put_list_get_play_delete(client: Client) -> None:
    name = "client-test.stroke"
    client.put_pattern(name, STROKE)
    assert name in {p.name for p in client.patterns()}
    assert client.get_pattern(name) == STROKE
    job = client.play_pattern(name, start_in_ms=10)
    assert client.job(job.job_id).state in JOB_STATES
    assert isinstance(client.touch(stored=name), Job)
    client.delete_pattern(name)
    with pytest.raises(NotFound):
        client.get_pattern(name)


def test_clips_put_list_get_play_delete(client: Client) -> None:
    clip = {
        "duration_s": 0.5,
        "amplitude": [{"t_s": 0.0, "value": 0.2}, {"t_s": 0.5, "value": 1.0}],
        "transients": [{"t_s": 0.1, "amplitude": 0.8, "frequency": 0.5}],
    }
    summary = client.put_clip("client-test.clip", clip)
    assert (summary.duration_s, summary.amplitude_points, summary.transients) == (0.5, 2, 1)
    assert "client-test.clip" in {c.name for c in client.clips()}
    assert client.get_clip("client-test.clip").transients[0].amplitude == 0.8
    stroke = TouchPattern.model_validate(
        {
            **STROKE.model_dump(exclude_unset=True),
            "carrier": {"kind": "clip", "clip": "client-test.clip"},
        }
    )
    assert isinstance(client.touch(stroke), Job)
    client.delete_clip("client-test.clip")
    with pytest.raises(InvalidRequest) as refused:  # a body naming a missing thing: 422
        client.touch(stroke)
    assert refused.value.fields[0]["field"] == "carrier.clip"


def test_tact_projects_put_page_get_play_delete(client: Client) -> None:
    def dot(length_ms: int) -> dict[str, object]:
        feedback = {
            "startTime": 0,
            "endTime": length_ms,
            "pointList": [{"index": 4, "intensity": 1}],
        }
        mode = {"mode": "DOT_MODE", "dotMode": {"feedback": [feedback]}}
        effect = {"startTime": 0, "offsetTime": length_ms, "modes": {"ForearmR": mode}}
        return {"project": {"tracks": [{"effects": [effect]}]}}

    for k in range(3):
        summary = client.put_tact(f"client-test.tact-{k}", dot(100 * (k + 1)))
        assert (summary.duration_s, summary.positions) == ((k + 1) / 10, ["ForearmR"])
    page = client.tact_projects(limit=2, offset=1)
    assert [p.name for p in page][:1] == ["client-test.tact-1"] and len(page) <= 2
    assert client.get_tact("client-test.tact-0") == dot(100)
    started = client.play_tact("client-test.tact-2", duration_scale=2, intensity_scale=0.5)
    assert (started.duration_s, len(started.job_ids)) == (0.6, 1)
    for k in range(3):
        client.delete_tact(f"client-test.tact-{k}")
    with pytest.raises(NotFound):
        client.play_tact("client-test.tact-0")


def test_wearers_put_list_get_delete(client: Client) -> None:
    offsets = {"sine_100hz": {2: 2.5, 5: -1.5}, "noise_40_500hz": {"2": 1.0}}
    stored = client.put_wearer("client-test.wearer", offsets, note="left forearm")
    assert stored.offsets_db == {"sine_100hz": {"2": 2.5, "5": -1.5}, "noise_40_500hz": {"2": 1.0}}
    listed = {w.name: w for w in client.wearers()}
    assert listed["client-test.wearer"].active is False
    assert client.get_wearer("client-test.wearer").note == "left forearm"
    with pytest.raises(InvalidRequest) as refused:
        client.put_wearer("client-test.bad", {"sine_100hz": {3: 25.0}})
    assert refused.value.fields[0]["field"] == "offsets_db.sine_100hz.3"
    client.delete_wearer("client-test.wearer")
    with pytest.raises(NotFound):
        client.get_wearer("client-test.wearer")


def test_the_client_chooses_the_wearer_while_the_service_runs(server: LiveServer) -> None:
    with Client(server.url) as pt:
        pt.put_wearer("client-test.chosen", {"sine_100hz": {2: 6.0, 8: -3.0}})
        chosen = pt.use_wearer("client-test.chosen", band="sine_100hz")
        assert (chosen.name, chosen.band) == ("client-test.chosen", "sine_100hz")
        assert chosen.offsets_db == pytest.approx([0.0, 6.0, 0, 0, 0, 0, 0, -3.0], abs=1e-5)
        assert pt.health().wearer == "client-test.chosen"
        with pytest.raises(InvalidRequest) as refused:
            pt.use_wearer("client-test.nobody")
        assert refused.value.fields[0]["field"] == "name"
        assert pt.wearer().name == "client-test.chosen"

    async def off() -> None:
        async with AsyncClient(server.url) as pt:
            assert (await pt.use_wearer("client-test.chosen")).name == "client-test.chosen"
            await pt.no_wearer()
            assert (await pt.wearer()).name is None
            assert (await pt.health()).wearer is None

    asyncio.run(off())
    with Client(server.url) as pt:
        assert pt.wearer().offsets_db == [0.0] * 8
        with pt.session(wearer="client-test.chosen") as ws:
            assert ws.welcome is not None
            assert ws.welcome.wearer == {"name": "client-test.chosen", "band": "sine_100hz"}
        assert pt.wearer().name == "client-test.chosen", "it stays when the session closes"
        pt.no_wearer()
        pt.delete_wearer("client-test.chosen")


def test_stop_and_metrics(client: Client) -> None:
    job = client.touch(preset="exp2/curved")
    client.stop()
    wait_until(
        lambda: client.job(job.job_id).state in {"stopped", "finished"},
        timeout_s=5,
        what="the job to stop",
    )
    text = client.metrics()
    assert "# TYPE" in text


def test_async_client(server: LiveServer) -> None:
    async def main() -> None:
        async with AsyncClient(server.url) as pt:
            assert (await pt.health()).status == "ok"
            job = await pt.touch(STROKE, start_in_ms=10)
            assert (await pt.job(job.job_id)).state in JOB_STATES
            assert "exp2/curved" in {p.name for p in await pt.presets()}

    asyncio.run(main())
