"""The chain after the voices: limiter, calibration, NaN guard, ceiling, meters."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern
from phantomtouch.engine import Engine
from phantomtouch.engine.mixer import THRESHOLD_RATIO, Limiter, Mixer
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.renderer import OutputStage
from phantomtouch.renderer.dc_blocker import DcBlocker
from phantomtouch.schema import Calibration, SafetyLimits

DEVICE = DeviceProfile(safety=SafetyLimits(ceiling=0.8))
BLOCK = DEVICE.block_frames
THRESHOLD = THRESHOLD_RATIO * 0.8


def block_with_peak(rng: np.random.Generator, peak: float) -> np.ndarray:
    block = rng.uniform(-1.0, 1.0, (BLOCK, DEVICE.channels)).astype(np.float32)
    block *= np.float32(peak / np.abs(block).max())
    return block


def test_the_limiter_is_exactly_transparent_below_its_threshold(rng: np.random.Generator) -> None:
    limiter = Limiter(DEVICE)
    for _ in range(20):
        block = block_with_peak(rng, 0.999 * THRESHOLD)
        untouched = block.copy()
        limiter.process(block)
        np.testing.assert_array_equal(block, untouched)
    assert limiter.limited_blocks == 0


def test_the_limiter_turns_loud_blocks_down_smoothly_then_recovers_to_transparent(
    rng: np.random.Generator,
) -> None:
    limiter = Limiter(DEVICE)
    loud = [block_with_peak(rng, 5.0) for _ in range(10)]
    quiet = [block_with_peak(rng, 0.5 * THRESHOLD) for _ in range(60)]
    gains = []
    for block in loud + quiet:
        before = block.copy()
        limiter.process(block)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = block / before
        gains.append(np.nanmax(ratio, axis=1))  # the same gain on every channel
    gain = np.concatenate(gains)
    attack = round(0.001 * DEVICE.sample_rate_hz)
    assert np.abs(np.concatenate(loud)[attack : 10 * BLOCK]).max() <= THRESHOLD * (1 + 1e-6)
    assert np.abs(np.diff(gain)).max() <= 1.0 / attack + 1e-6  # no step: a ramp
    recovery = np.diff(gain[10 * BLOCK :])
    assert recovery.min() >= -1e-7 and recovery.max() <= 1.0 / (0.1 * 48000) + 1e-6
    assert gain[-1] == 1.0 and limiter.gain == 1.0
    last = block_with_peak(rng, 0.5 * THRESHOLD)
    untouched = last.copy()
    limiter.process(last)
    np.testing.assert_array_equal(last, untouched)  # transparent again
    assert limiter.limited_blocks >= 10


def test_the_limiter_looks_at_calibrated_levels(rng: np.random.Generator) -> None:
    device = DeviceProfile(
        safety=SafetyLimits(ceiling=0.8),
        calibration=Calibration(channel_level_db=(149.0,) + (155.0,) * 7),
    )
    limiter = Limiter(device)
    block = block_with_peak(rng, 0.5)  # 0.5 x 2 (6 dB weaker actuator) > threshold
    limiter.process(block)
    assert limiter.limited_blocks == 1 and limiter.gain < 1.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_block_with_nan_or_inf_is_muted_and_counted(rng: np.random.Generator, bad: float) -> None:
    mixer = Mixer(DEVICE)
    block = block_with_peak(rng, 0.5)
    block[17, 3] = bad
    mixer.finish(block)
    assert not np.any(block)
    assert mixer.stage.muted_blocks == 1
    assert mixer.limiter.gain == 1.0  # the limiter's state is not poisoned
    good = block_with_peak(rng, 0.5)
    expected = good.copy()
    mixer.finish(good)
    np.testing.assert_array_equal(good, expected)
    assert mixer.stage.muted_blocks == 1


def test_the_meters_report_the_output_peaks(rng: np.random.Generator) -> None:
    mixer = Mixer(DEVICE)
    block = block_with_peak(rng, 0.3)
    mixer.finish(block)
    np.testing.assert_array_equal(mixer.levels, np.abs(block).max(axis=0))
    assert mixer.peak == pytest.approx(0.3)
    mixer.finish(block_with_peak(rng, 0.1))
    assert mixer.peak == pytest.approx(0.3) and mixer.levels.max() == pytest.approx(0.1)


@pytest.fixture
def loud_engine() -> Iterator[tuple[Engine, CaptureSink]]:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, max_voices=50) as engine:  # 50 patterns at once, above the default
        yield engine, sink


def test_a_hundred_full_level_voices_stay_under_the_ceiling(
    loud_engine: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = loud_engine
    pattern = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 7.2], [1.9, 8.0]]},
            "duration_s": 0.2,
            "fade_in_s": 0.0,
            "fade_out_s": 0.0,
            "intensity": 1.0,
        }
    )
    for k in range(50):
        engine.schedule(pattern, start_frame=BLOCK + 7 * k)
        engine.contact_down("all", f"c{k}", 1.9, 7.2 + 0.01 * k, intensity=1.0, at_frame=BLOCK)
    recording = sink.pull(50)
    status = engine.status()
    assert np.abs(recording).max() <= 0.8
    assert np.abs(recording).max() >= 0.7  # limited, not muted
    assert status.active_voices == 50 and status.limited_blocks > 0
    assert status.muted_blocks == 0 and status.peak <= 0.8


def blocks_of_every_kind(rng: np.random.Generator) -> list[np.ndarray]:
    """Quiet, near the threshold, loud (limited), past the ceiling, NaN/Inf, short blocks."""
    blocks = []
    for peak in [0.1, 0.5, 0.999 * THRESHOLD, THRESHOLD, 1.001 * THRESHOLD, 2.0, 50.0]:
        blocks.append(block_with_peak(rng, peak))
    blocks += [block_with_peak(rng, 0.3) for _ in range(30)]  # the limiter recovers
    for bad in [np.nan, np.inf, -np.inf]:
        block = block_with_peak(rng, 0.2)
        block[rng.integers(BLOCK), rng.integers(DEVICE.channels)] = bad
        blocks.append(block)
    silent = np.zeros((BLOCK, DEVICE.channels), dtype=np.float32)
    blocks += [silent, -silent, block_with_peak(rng, 0.4)[:100], block_with_peak(rng, 3.0)[:7]]
    blocks += [block_with_peak(rng, peak) for peak in rng.uniform(0.0, 1.2, 60)]
    return blocks


@pytest.mark.parametrize(
    "calibration",
    [
        Calibration(),
        Calibration(channel_level_db=(149.0, 152.0, 155.0, 158.0, 161.0, 150.0, 155.0, 156.0)),
        Calibration(fir_taps=((0.5, 0.3, 0.2),) + ((1.0,),) * 7),
    ],
)
def test_the_mixer_gives_the_whole_chains_samples_and_levels_for_every_block(
    rng: np.random.Generator, calibration: Calibration
) -> None:
    device = DEVICE.model_copy(update={"calibration": calibration})
    mixer = Mixer(device)
    limiter, stage = Limiter(device), OutputStage(device)  # the whole chain, every block
    blocker = DcBlocker(device.channels, device.sample_rate_hz, device.safety.ceiling)
    peak = 0.0
    for block in blocks_of_every_kind(rng):
        expected = block.copy()
        blocker.process(expected)
        limiter.process(expected)
        stage.process(expected)
        levels = np.abs(expected).max(axis=0)
        peak = max(peak, float(levels.max()))
        mixer.finish(block)
        np.testing.assert_array_equal(block.view(np.uint32), expected.view(np.uint32))  # bits
        np.testing.assert_array_equal(mixer.levels.view(np.uint32), levels.view(np.uint32))
        assert mixer.peak == peak
        assert mixer.limiter.gain == limiter.gain
        assert (mixer.limiter.limited_blocks, mixer.stage.muted_blocks) == (
            limiter.limited_blocks,
            stage.muted_blocks,
        )
    assert limiter.limited_blocks > 0 and stage.muted_blocks == 3
