"""The wearer's per-channel gains at the output stage: set at a block boundary, ramped
over ``WEARER_RAMP_S``, bit for bit absent while every gain is 1."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from phantomtouch import DeviceProfile
from phantomtouch.engine import Engine
from phantomtouch.engine.messages import AudioState, SetWearerGains, perform
from phantomtouch.engine.mixer import WEARER_RAMP_S, Mixer
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.errors import ParameterError
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.output.soundcard import SinkSpec

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
CHANNELS = DEVICE.channels


def quiet_block(rng: np.random.Generator) -> np.ndarray:
    """A block well within the limiter's threshold (its gain stays 1)."""
    return rng.uniform(-0.1, 0.1, (BLOCK, CHANNELS)).astype(np.float32)


def test_unity_gains_change_no_sample(rng: np.random.Generator) -> None:
    plain, fitted = Mixer(DEVICE), Mixer(DEVICE)
    fitted.wearer.set(np.ones(CHANNELS, dtype=np.float32))
    for _ in range(3):
        block = quiet_block(rng)
        a, b = block.copy(), block.copy()
        plain.finish(a)
        fitted.finish(b)
        assert np.array_equal(a, b)


def _ratios(
    fitted: Mixer, blocks: int, rng: np.random.Generator, at: dict[int, np.ndarray]
) -> np.ndarray:
    """Per-sample gain of ``fitted`` against an unfitted mixer over ``blocks`` blocks,
    ``at[k]`` set before block ``k``; shape (frames, channels), float64."""
    plain = Mixer(DEVICE)
    ratios = []
    for k in range(blocks):
        if k in at:
            fitted.wearer.set(at[k])
        block = quiet_block(rng)
        a, b = block.copy(), block.copy()
        plain.finish(a)
        fitted.finish(b)
        ratios.append(b.astype(np.float64) / a)
    return np.concatenate(ratios)


def test_a_change_ramps_over_the_ramp_time_then_holds(rng: np.random.Generator) -> None:
    gains = np.linspace(0.5, 2.0, CHANNELS).astype(np.float32)
    fitted = Mixer(DEVICE)
    ramp = fitted.wearer.ramp_frames
    assert ramp == round(WEARER_RAMP_S * DEVICE.sample_rate_hz) > BLOCK  # several blocks
    ratio = _ratios(fitted, -(-ramp // BLOCK) + 2, rng, {0: gains})
    frames = np.arange(1, len(ratio) + 1)[:, None]
    expected = 1.0 + (gains.astype(np.float64) - 1.0) * np.minimum(frames / ramp, 1.0)
    # float32 samples divided by float32 samples: 1e-5 relative
    np.testing.assert_allclose(ratio, expected, rtol=1e-5)
    np.testing.assert_allclose(
        ratio[ramp - 1 :], np.broadcast_to(gains, ratio[ramp - 1 :].shape), rtol=1e-6
    )
    largest_step = np.max(np.abs(np.diff(ratio, axis=0)), axis=0)
    # each ratio carries float32 rounding of about 1e-7 (samples near 0.1): 1e-6 absolute
    np.testing.assert_allclose(largest_step, np.abs(gains - 1.0) / ramp, rtol=0, atol=1e-6)


def test_changes_at_every_block_never_step_the_gain(rng: np.random.Generator) -> None:
    """975 switches a second swung the gains by 40 dB at block rate: now each change ramps
    from where the gains are, so no frame moves by more than the swing over the ramp."""
    loud = np.full(CHANNELS, 10.0, dtype=np.float32)  # +20 dB
    soft = np.full(CHANNELS, 0.1, dtype=np.float32)  # -20 dB
    fitted = Mixer(DEVICE)
    at = {k: loud if k % 2 == 0 else soft for k in range(40)}
    ratio = _ratios(fitted, 40, rng, at)
    steps = np.abs(np.diff(ratio, axis=0))
    # the largest move a ramp allows per frame, 9.9 / ramp, with float32 rounding
    assert steps.max() <= (10.0 - 0.1) / fitted.wearer.ramp_frames * (1 + 1e-4)


def test_the_applier_sets_the_gains_even_after_a_stop() -> None:
    with Engine(DEVICE, sink=CaptureSink(DEVICE)) as engine:
        state = AudioState(core=engine._audio.core)  # type: ignore[union-attr]
        gains = np.full(CHANNELS, 2.0, dtype=np.float32)
        perform(state, SetWearerGains(gains), void=True)
        mixer = engine._audio.core.scheduler.mixer  # type: ignore[union-attr]
        for _ in range(-(-mixer.wearer.ramp_frames // BLOCK)):  # through the ramp
            mixer.wearer.apply(np.full((BLOCK, CHANNELS), 0.1, dtype=np.float32))
        assert np.array_equal(mixer.wearer.gains, gains)


@pytest.mark.parametrize(
    ("gains", "field"),
    [
        ([1.0] * (CHANNELS - 1), "shape"),
        ([1.0] * (CHANNELS - 1) + [float("nan")], f"gains[{CHANNELS - 1}]"),
        ([0.0] + [1.0] * (CHANNELS - 1), "gains[0]"),
        ([-1.0] + [1.0] * (CHANNELS - 1), "gains[0]"),
        ("loud", "gains"),
    ],
)
def test_bad_gains_are_refused_naming_the_channel(gains: object, field: str) -> None:
    with Engine(DEVICE, sink=CaptureSink(DEVICE)) as engine, pytest.raises(ParameterError) as err:
        engine.set_wearer_gains(gains)
    assert field in str(err.value)


def _level_ratio(engine: ProcessEngine) -> float:
    """Channel 1's output peak over channel 2's, with equal contacts on both actuators."""
    first, second = DEVICE.actuators[0], DEVICE.actuators[1]
    engine.contact_down("w", "1", first.x_cm, first.y_cm)
    engine.contact_down("w", "2", second.x_cm, second.y_cm)
    time.sleep(0.3)  # past the attack: steady sines
    levels = engine.status().levels
    engine.release_owner("w")
    return levels[0] / levels[1]


def test_the_engine_process_keeps_the_wearer_gains_across_a_restart() -> None:
    gains = np.ones(CHANNELS)
    gains[0] = 2.0
    engine = ProcessEngine(DEVICE, SinkSpec("null"))
    try:
        engine.start()
        assert _level_ratio(engine) == pytest.approx(1.0, rel=1e-3)
        engine.set_wearer_gains(gains)
        assert _level_ratio(engine) == pytest.approx(2.0, rel=1e-3)
        old_pid = engine.pid
        assert old_pid is not None
        os.kill(old_pid, signal.SIGKILL)
        deadline = time.monotonic() + 30.0
        while not (engine.pid != old_pid and engine.state == "running"):
            assert time.monotonic() < deadline, "the engine process was not restarted"
            time.sleep(0.01)
        assert _level_ratio(engine) == pytest.approx(2.0, rel=1e-3)
    finally:
        engine.close()
