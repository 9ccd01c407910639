"""The engine at 64-frame blocks (``--period 64``, 1.3 ms at 48 kHz): what the tests at
the profile's 256 frames pin, at 64 — ``render()`` is what the engine plays, contact
attacks and ramps, impact transients, the limiter's ceiling and the wearer's ramps.

The engine gets its block from a capture sink asked for 64-frame periods, as ``--period
64`` gives it on an output without a period of its own.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import ContactSettings, Engine
from phantomtouch.engine.mixer import WEARER_RAMP_S, Mixer
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.renderer.carriers import SineSource
from phantomtouch.renderer.levels import amplitude_for_level

PROFILE = DeviceProfile.default()
BLOCK = 64
DEVICE = PROFILE.at_block(BLOCK)
RATE = PROFILE.sample_rate_hz
CHANNELS = PROFILE.channels
ATTACK = round(0.01 * RATE)
HALF = amplitude_for_level(PROFILE.safety.max_level_db + 20 * math.log10(0.5), PROFILE)
FLOAT32 = 1e-7
"""Gains, ramps and envelopes are float32: a few ulps of 1 (6e-8), times an amplitude < 1."""


def sine(frames: int, offset: int = 0) -> np.ndarray:
    return SineSource(100.0, RATE).block(offset, frames).astype(np.float64)


@pytest.fixture
def captured() -> Iterator[tuple[Engine, CaptureSink]]:
    sink = CaptureSink(PROFILE, period_frames=BLOCK)
    with Engine(PROFILE, sink, voice_cost=0.01) as engine:
        assert engine.block_frames == BLOCK and engine.status().period_source == "option"
        yield engine, sink


def stroke(**changes: object) -> TouchPattern:
    fields: dict[str, object] = {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 40.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
    }
    fields.update(changes)
    return TouchPattern.model_validate(fields)


@pytest.mark.parametrize("prerender_max_s", [0.0, 2.0], ids=["in-the-callback", "prerendered"])
@pytest.mark.parametrize("render_ahead_frames", [0, 8192], ids=["block-by-block", "rings"])
def test_what_the_engine_plays_at_64_frames_is_exactly_render(
    prerender_max_s: float, render_ahead_frames: int
) -> None:
    sine_stroke = stroke()
    noise_stroke = stroke(carrier={"kind": "noise", "seed": 11}, intensity="high")
    sink = CaptureSink(PROFILE, period_frames=BLOCK)
    engine = Engine(
        PROFILE,
        sink,
        voice_cost=0.01,
        prerender_max_s=prerender_max_s,
        render_ahead_frames=render_ahead_frames,
    )
    with engine:
        first = engine.schedule(noise_stroke, start_frame=5 * BLOCK)  # on a block boundary
        second = engine.schedule(sine_stroke, start_frame=9 * BLOCK + 23)  # inside a block
        frames = second.start_frame + second.frames + 4 * BLOCK
        recording = sink.pull(-(-frames // BLOCK))
        late = engine.status().late_commands
    assert late == 0
    expected = np.zeros_like(recording)
    for job, pattern in ((first, noise_stroke), (second, sine_stroke)):
        samples = render(pattern, PROFILE)
        expected[job.start_frame : job.start_frame + len(samples)] += samples
    # two overlapping voices: their float32 sum, in the mixer's order or the test's
    np.testing.assert_allclose(recording, expected, rtol=0, atol=FLOAT32)
    alone = recording[first.start_frame : second.start_frame]
    reference = render(noise_stroke, PROFILE)[: len(alone)]
    np.testing.assert_array_equal(alone, reference)  # one voice alone: bit-exact


def test_touchdown_fades_in_over_the_attack_from_its_sample_at_64_frames(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    down = 3 * BLOCK + 17
    engine.contact_down("c", "f", 0.0, 4.8, intensity=0.5, at_frame=down)  # actuator 2
    recording = sink.pull(ATTACK // BLOCK + 8).astype(np.float64)
    n = len(recording) - down
    attack = np.minimum(1.0, np.arange(1, n + 1) / ATTACK)
    assert not np.any(recording[:down])
    np.testing.assert_allclose(recording[down:, 1], HALF * attack * sine(n), atol=FLOAT32)
    assert not np.any(np.delete(recording, 1, axis=1))


def test_a_move_ramps_the_gains_across_one_64_frame_block(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 0.0, intensity=0.5, at_frame=0)  # actuator 1
    settled = ATTACK // BLOCK + 2
    sink.pull(settled)
    engine.contact_move("c", "f", 0.0, 4.8)  # to actuator 2
    block = sink.pull(2).astype(np.float64)
    ramp = np.arange(1, BLOCK + 1) / BLOCK
    carrier = sine(2 * BLOCK, settled * BLOCK)
    np.testing.assert_allclose(block[:BLOCK, 0], HALF * (1 - ramp) * carrier[:BLOCK], atol=FLOAT32)
    np.testing.assert_allclose(block[:BLOCK, 1], HALF * ramp * carrier[:BLOCK], atol=FLOAT32)
    np.testing.assert_allclose(block[BLOCK:, 1], HALF * carrier[BLOCK:], atol=FLOAT32)
    assert not np.any(block[BLOCK:, 0])


def test_an_impact_transient_at_64_frames_is_the_decaying_sinusoid() -> None:
    release = round(ContactSettings().release_s * RATE)

    def play(down_m_s: float | None, up_m_s: float | None) -> np.ndarray:
        sink = CaptureSink(PROFILE, period_frames=BLOCK)
        with Engine(PROFILE, sink, voice_cost=0.01) as engine:
            engine.contact_down(
                "c", "f", 0.0, 2.4, intensity=0.5, normal_velocity_m_s=down_m_s, at_frame=50
            )
            engine.contact_up("c", "f", normal_velocity_m_s=up_m_s, at_frame=80 * BLOCK + 5)
            return sink.pull(120 + release // BLOCK).astype(np.float64)

    plain, struck = play(None, None), play(0.25, -1.0)
    burst = struck - plain
    settings = ContactSettings()
    t = np.arange(math.ceil(7 * settings.transient_decay_s * RATE)) / RATE
    shape = np.exp(-t / settings.transient_decay_s) * np.sin(2 * np.pi * 250.0 * t)
    unit = np.sqrt(0.5)  # halfway between actuators 1 and 2: power law
    for at, scale in ((50, 0.5), (80 * BLOCK + 5, 1.0)):  # 0.25 of 0.5 m/s; |-1| saturates
        for channel in (0, 1):
            np.testing.assert_allclose(
                burst[at : at + len(t), channel], scale * HALF * unit * shape, atol=2e-7
            )
        burst[at : at + len(t)] = 0.0
    assert np.abs(burst).max() < 1e-7  # nothing else changed


def test_full_level_voices_and_contacts_stay_under_the_ceiling_at_64_frames() -> None:
    pattern = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 7.2], [1.9, 8.0]]},
            "duration_s": 0.2,
            "fade_in_s": 0.0,
            "fade_out_s": 0.0,
            "intensity": 1.0,
        }
    )
    sink = CaptureSink(PROFILE, period_frames=BLOCK)
    with Engine(PROFILE, sink, max_voices=50, voice_cost=0.01) as engine:
        for k in range(50):
            engine.schedule(pattern, start_frame=BLOCK + 7 * k)
            engine.contact_down("all", f"c{k}", 1.9, 7.2 + 0.01 * k, intensity=1.0, at_frame=BLOCK)
        recording = sink.pull(200)
        status = engine.status()
    ceiling = PROFILE.safety.ceiling
    assert np.all(np.isfinite(recording))
    assert np.abs(recording).max() <= ceiling
    assert np.abs(recording).max() >= 0.875 * ceiling  # limited, not muted
    assert status.limited_blocks > 0 and status.muted_blocks == 0


def test_the_wearers_gains_ramp_over_the_ramp_time_in_64_frame_blocks(
    rng: np.random.Generator,
) -> None:
    gains = np.linspace(0.5, 2.0, CHANNELS).astype(np.float32)
    plain, fitted = Mixer(DEVICE), Mixer(DEVICE)
    ramp = fitted.wearer.ramp_frames
    assert ramp == round(WEARER_RAMP_S * RATE) > 4 * BLOCK  # many 64-frame blocks
    fitted.wearer.set(gains)
    ratios = []
    for _ in range(-(-ramp // BLOCK) + 2):
        block = rng.uniform(-0.1, 0.1, (BLOCK, CHANNELS)).astype(np.float32)
        a, b = block.copy(), block.copy()
        plain.finish(a)
        fitted.finish(b)
        ratios.append(b.astype(np.float64) / a)
    ratio = np.concatenate(ratios)
    frames = np.arange(1, len(ratio) + 1)[:, None]
    expected = 1.0 + (gains.astype(np.float64) - 1.0) * np.minimum(frames / ramp, 1.0)
    # float32 samples divided by float32 samples: 1e-5 relative
    np.testing.assert_allclose(ratio, expected, rtol=1e-5)
