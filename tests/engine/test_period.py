"""The engine renders the sound card's period: JACK's server period (or a divisor of it
asked with ``--period``), the buffer other host APIs report, else the profile's block.

The JACK tests run against a private dummy server at 128 and at 64 frames: the engine's
block follows the server whatever the profile says, each callback is one period, and what
reaches JACK is exactly ``render()``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import Engine, ProcessEngine
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.output.devices import find_output_device, host_period_frames
from phantomtouch.output.sinks import NullSink
from phantomtouch.output.soundcard import SinkSpec, SoundDeviceSink, resolve_period
from tests.support.jack import JackRecorder, JackServer, start_jack_or_skip
from tests.support.live_server import LiveServer

JACK = "JACK Audio Connection Kit"
PROFILE = DeviceProfile.default()  # block_frames 256: the period is not the profile's
RATE = PROFILE.sample_rate_hz


@pytest.fixture(scope="module", params=[128, 64], ids=["jack-128", "jack-64"])
def jack_at(request: pytest.FixtureRequest) -> Iterator[JackServer]:
    """A JACK dummy server at 48 kHz and 128 or 64-frame periods."""
    server = start_jack_or_skip(sample_rate_hz=RATE, period_frames=request.param, channels=8)
    yield server
    server.stop()


@pytest.mark.parametrize(
    ("host_api", "host_period", "asked", "expected"),
    [
        (JACK, 128, None, (128, 128, "backend")),
        (JACK, 128, 64, (128, 64, "option")),  # two blocks in each callback
        (JACK, 64, 64, (64, 64, "option")),
        ("Windows WASAPI", 480, None, (480, 480, "backend")),
        ("ASIO", 256, 64, (64, 64, "option")),  # PortAudio opens ASIO at the block asked
        ("ALSA", None, None, (256, 256, "profile")),
        ("ALSA", None, 64, (64, 64, "option")),
    ],
)
def test_the_period_is_the_backends_unless_one_is_asked_for(
    host_api: str,
    host_period: int | None,
    asked: int | None,
    expected: tuple[int, int, str],
) -> None:
    assert resolve_period(host_api, host_period, asked, 256) == expected


def test_a_period_that_does_not_divide_jacks_is_refused_with_the_server_period() -> None:
    with pytest.raises(DeviceError, match=r"period_frames=96 must divide .* 128 frames"):
        resolve_period(JACK, 128, 96, 256)
    with pytest.raises(DeviceError, match=r"period_frames=256 must divide .* 128 frames"):
        resolve_period(JACK, 128, 256, 256)


@pytest.mark.parametrize("asked", [8, 8193, 64.0, True])
def test_a_period_out_of_range_is_refused_naming_the_range(asked: object) -> None:
    with pytest.raises(
        ParameterError, match=r"period_frames=.* must be an integer in \[16, 8192\]"
    ):
        resolve_period("ALSA", None, asked, 256)  # type: ignore[arg-type]


def test_host_apis_whose_latency_is_no_buffer_have_no_period() -> None:
    listed = {"hostapi": "ALSA", "low_latency_s": 0.0058, "default_samplerate": 48000.0}
    assert host_period_frames(listed) is None
    wasapi = {"hostapi": "Windows WASAPI", "low_latency_s": 0.003, "default_samplerate": 48000.0}
    assert host_period_frames(wasapi) == 144


def test_the_jack_device_reports_the_servers_period(jack_at: JackServer) -> None:
    system = find_output_device("system", 8)
    assert host_period_frames(system) == jack_at.period_frames


def test_the_engine_renders_jacks_period_whatever_the_profile_says(jack_at: JackServer) -> None:
    period = jack_at.period_frames
    sink = SoundDeviceSink(PROFILE, "system")
    assert (sink.period_frames, sink.block_frames, sink.period_source) == (
        period,
        period,
        "backend",
    )
    with Engine(PROFILE, sink, voice_cost=0.01) as engine:
        assert engine.device.block_frames == engine.block_frames == period
        deadline = time.monotonic() + 10.0
        while engine.now_frames < 40 * period:
            assert time.monotonic() < deadline, "the engine did not play"
            time.sleep(0.01)
        status = engine.status()
        rendered = engine.core.scheduler.render_seconds
    assert (status.block_frames, status.period_frames, status.period_source) == (
        period,
        period,
        "backend",
    )
    assert 0.0 < status.callback_p50_s <= status.callback_p99_s <= status.callback_max_s
    # the load is the callback's time over one period's playing time
    timed = rendered[~np.isnan(rendered)]
    assert timed.size >= 40
    loads = engine.core.scheduler.render_loads[~np.isnan(engine.core.scheduler.render_loads)]
    np.testing.assert_allclose(loads, timed * RATE / period, rtol=1e-12)


def stroke() -> TouchPattern:
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
            "speed_cm_s": 40.0,
            "fade_in_s": 0.05,
            "fade_out_s": 0.05,
            "carrier": {"kind": "noise", "seed": 3},
        }
    )


@pytest.mark.parametrize("divisor", [1, 2], ids=["one-block", "two-blocks-a-callback"])
@pytest.mark.parametrize("prerender_max_s", [0.0, 2.0], ids=["in-the-callback", "prerendered"])
def test_what_reaches_jack_at_its_period_is_exactly_render(
    jack_at: JackServer, divisor: int, prerender_max_s: float
) -> None:
    period = jack_at.period_frames
    block = period // divisor
    pattern = stroke()
    reference = render(pattern, PROFILE)
    sink = SoundDeviceSink(PROFILE, "system", period_frames=None if divisor == 1 else block)
    recorder = JackRecorder(jack_at, channels=8, max_frames=4 * RATE)
    assert len(recorder.connect_from("PortAudio")) == 8
    engine = Engine(PROFILE, sink, voice_cost=0.01, prerender_max_s=prerender_max_s)
    assert (engine.block_frames, sink.period_frames) == (block, period)
    try:
        job = engine.schedule(pattern, start_frame=0)
        engine.start()
        deadline = time.monotonic() + 10.0
        while engine.now_frames < job.frames + 8 * period:
            assert time.monotonic() < deadline, "the engine did not play the pattern"
            time.sleep(0.01)
        late = engine.status().late_commands
    finally:
        engine.close()
        recording = recorder.close()
    assert late == 0
    heard = np.flatnonzero(np.any(recording != 0.0, axis=1))
    assert heard.size > 0
    at = int(heard[0]) - int(np.flatnonzero(np.any(reference != 0.0, axis=1))[0])
    np.testing.assert_array_equal(recording[at : at + len(reference)], reference)
    assert not np.any(recording[at + len(reference) :])  # nothing after it


def test_a_null_output_plays_the_period_asked_or_the_profiles_block() -> None:
    with Engine(PROFILE, NullSink(PROFILE, period_frames=64), voice_cost=0.01) as engine:
        assert (engine.block_frames, engine.status().period_source) == (64, "option")
    with Engine(PROFILE, NullSink(PROFILE), voice_cost=0.01) as engine:
        assert (engine.block_frames, engine.status().period_source) == (256, "profile")
    spec = SinkSpec("null", period_frames=64)  # in an engine process: told with its ready
    with ProcessEngine(PROFILE, spec, voice_cost=0.01) as engine:
        status = engine.status()
        assert engine.device == PROFILE.at_block(64)
        assert (status.block_frames, status.period_frames, status.period_source) == (
            64,
            64,
            "option",
        )


def test_the_engine_process_plays_at_the_period_its_sink_found(jack_at: JackServer) -> None:
    period = jack_at.period_frames
    engine = ProcessEngine(PROFILE, SinkSpec("sounddevice", output="system"), voice_cost=0.01)
    try:
        engine.start()
        assert engine.device.block_frames == engine.block_frames == period
        deadline = time.monotonic() + 10.0
        while engine.status().callback_p99_s <= 0.0:
            assert time.monotonic() < deadline, "no callback was timed"
            time.sleep(0.02)
        status = engine.status()
    finally:
        engine.close()
    assert (status.period_frames, status.block_frames, status.period_source) == (
        period,
        period,
        "backend",
    )
    assert 0.0 < status.callback_p50_s <= status.callback_p99_s <= status.callback_max_s


def test_get_device_and_metrics_show_the_period_and_the_callbacks_time(
    jack_at: JackServer, tmp_path: Path
) -> None:
    period = jack_at.period_frames
    service = LiveServer(
        tmp_path / "p.db", output="system", args=("--period", "32"), log_path=tmp_path / "log"
    )
    service.start()
    try:
        device = httpx.get(f"{service.url}/device", timeout=10.0).json()
        time.sleep(0.3)  # a few hundred callbacks timed
        metrics = httpx.get(f"{service.url}/metrics", timeout=10.0).text
        schema = httpx.get(f"{service.url}/openapi.json", timeout=10.0).json()
    finally:
        service.stop()
    assert (device["block_frames"], device["period_frames"], device["period_source"]) == (
        32,
        period,
        "option",
    )
    fields = schema["components"]["schemas"]["DeviceInfo"]["properties"]
    assert fields["period_source"]["enum"] == ["backend", "option", "profile"]
    assert "period_frames" in schema["components"]["schemas"]["DeviceInfo"]["required"]
    assert f"phantomtouch_period_frames {period}.0" in metrics
    quantiles = {
        line.split('"')[1]: float(line.rsplit(" ", 1)[1])
        for line in metrics.splitlines()
        if line.startswith("phantomtouch_callback_seconds{")
    }
    assert set(quantiles) == {"0.5", "0.99", "1"}
    assert 0.0 < quantiles["0.5"] <= quantiles["0.99"] <= quantiles["1"]
