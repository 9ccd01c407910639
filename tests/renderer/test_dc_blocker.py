"""The DC blocker: a one-pole high-pass beyond a dead band (renderer/dc_blocker.py).

Analytic properties: beyond the dead band the output is the one-pole high-pass plus the
band's edge, whose response is 0 at DC and about 1 in the carriers' band; within it the
blocker changes no sample; blocks of any size give the whole run's samples, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from phantomtouch.renderer.dc_blocker import DC_BLOCK_HZ, DC_DEAD_BAND, DcBlocker
from phantomtouch.schema import limits

FS = 48_000
CHANNELS = 2


def run(blocker: DcBlocker, signal: np.ndarray, block: int) -> np.ndarray:
    out = signal.astype(np.float32).copy()
    for at in range(0, len(out), block):
        blocker.process(out[at : at + block])
    return out


def test_the_response_is_zero_at_dc_and_one_in_the_carriers_band() -> None:
    blocker = DcBlocker(CHANNELS, FS, 1.0)
    freqs_hz = np.array([0.0, limits.MIN_CARRIER_HZ, 50.0, 100.0, 250.0, 1000.0])
    gain = blocker.response(freqs_hz, FS)
    assert gain[0] == 0.0
    # a one-pole high-pass: |H(f)| ~ f / sqrt(f**2 + fc**2), 0.99969 at 20 Hz
    corner = DC_BLOCK_HZ / freqs_hz[1:]
    np.testing.assert_allclose(gain[1:], 1.0 / np.sqrt(1.0 + corner**2), rtol=1e-4)
    assert gain[1:].min() > 0.9996


def test_a_dc_offset_beyond_the_dead_band_decays_to_its_edge_with_the_time_constant() -> None:
    blocker = DcBlocker(CHANNELS, FS, 1.0)
    seconds = 4.0
    offset = 0.8  # near full scale: the attack of a 0.01 Hz sine, for seconds
    signal = np.full((int(seconds * FS), CHANNELS), offset)
    out = run(blocker, signal, 128)
    tau_s = 1.0 / (2.0 * math.pi * DC_BLOCK_HZ)
    t_s = np.arange(len(out)) / FS
    # m = offset (1 - r**(n+1)); beyond the band y = x - m + b = b + offset r**(n+1)
    expected = DC_DEAD_BAND + offset * np.exp(-(t_s + 1.0 / FS) / tau_s)
    beyond = offset * (1 - np.exp(-(t_s + 1.0 / FS) / tau_s)) > DC_DEAD_BAND
    # float32 samples: 1e-6 absolute
    np.testing.assert_allclose(out[beyond, 0], expected[beyond], atol=2e-6)
    assert abs(float(out[-1, 0]) - DC_DEAD_BAND) < 1e-4  # at the band's edge for good
    assert blocker.blocked_blocks > 0


def test_with_a_dc_offset_the_carrier_passes_through_the_high_pass() -> None:
    """DC plus a 100 Hz sine: once the offset has decayed, the sine is there at |H|."""
    blocker = DcBlocker(CHANNELS, FS, 1.0)
    t_s = np.arange(4 * FS) / FS
    sine = 0.2 * np.sin(2 * np.pi * 100.0 * t_s)
    out = run(blocker, (0.6 + sine)[:, None].repeat(CHANNELS, axis=1), 256)
    tail = out[-FS:, 0].astype(np.float64) - DC_DEAD_BAND
    rms = math.sqrt(float(np.mean(tail**2)))
    assert rms == pytest.approx(
        0.2 / math.sqrt(2) * blocker.response(np.array([100.0]), FS)[0], rel=2e-3
    )


@pytest.mark.parametrize("freq_hz", [limits.MIN_CARRIER_HZ, 50.0, 150.0])
def test_a_full_scale_carrier_from_rest_passes_bit_for_bit(freq_hz: float) -> None:
    """Within the dead band nothing changes: the engine plays render()'s samples."""
    blocker = DcBlocker(CHANNELS, FS, 1.0)
    t_s = np.arange(2 * FS) / FS
    for phase in (0.0, np.pi / 2, np.pi):
        signal = np.sin(2 * np.pi * freq_hz * t_s + phase)[:, None].repeat(CHANNELS, axis=1)
        out = run(blocker, signal, 128)
        np.testing.assert_array_equal(out, signal.astype(np.float32))
    assert blocker.blocked_blocks == 0


def test_blocks_of_any_size_give_the_whole_runs_samples(rng: np.random.Generator) -> None:
    t_s = np.arange(FS) / FS
    signal = (0.7 + 0.2 * np.sin(2 * np.pi * 30.0 * t_s))[:, None] + 0.05 * rng.standard_normal(
        (FS, CHANNELS)
    )
    whole = run(DcBlocker(CHANNELS, FS, 1.0), signal, len(signal))
    for block in (1, 7, 128, 1000):
        np.testing.assert_array_equal(run(DcBlocker(CHANNELS, FS, 1.0), signal, block), whole)
    assert not np.array_equal(whole, signal.astype(np.float32))  # it did act


def test_a_nan_block_does_not_poison_the_state() -> None:
    blocker = DcBlocker(CHANNELS, FS, 1.0)
    bad = np.full((128, CHANNELS), np.nan, dtype=np.float32)
    blocker.process(bad)
    quiet = np.full((128, CHANNELS), 0.01, dtype=np.float32)
    blocker.process(quiet)
    assert np.isfinite(quiet).all()


def test_the_closed_form_carries_the_low_pass_state_of_the_whole_run(
    rng: np.random.Generator,
) -> None:
    """Over blocks within the dead band the state advances in closed form (a compiled
    loop), and stays the one-pole low-pass ``m[n] = (1 - r) x[n] + r m[n-1]`` run sample
    by sample (the state kept is ``z = r m``), to float64 rounding."""
    blocker = DcBlocker(CHANNELS, FS, 1.0)
    t_s = np.arange(20 * 128) / FS
    signal = (0.5 * np.sin(2 * np.pi * 100.0 * t_s)[:, None] * [1.0, 0.3]).astype(np.float32)
    signal += (0.002 * rng.standard_normal(signal.shape)).astype(np.float32)
    out = signal.copy()
    for at in range(0, len(out), 128):
        assert not blocker.process(out[at : at + 128])  # plain: left as it is
    np.testing.assert_array_equal(out, signal)
    r = blocker.pole
    low = np.zeros(CHANNELS)
    for x in signal.astype(np.float64):
        low = (1.0 - r) * x + r * low
    np.testing.assert_allclose(blocker._state[0], r * low, rtol=1e-9, atol=1e-15)
