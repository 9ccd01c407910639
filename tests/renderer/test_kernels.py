"""The compiled loops of the callback's chain (renderer/kernels.py), against the formulas
they stand for: the contacts' sum is ``c @ s + ramp * (c @ (t - s))`` rounded once to
float32;
a block that is not plain leaves the block and the DC state as they were."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch.renderer import kernels
from phantomtouch.renderer.dc_blocker import DcBlocker

FRAMES, CHANNELS, CONTACTS = 128, 8, 5


@pytest.mark.parametrize("add", [False, True])
@pytest.mark.parametrize("moved", [False, True])
def test_the_contacts_sum_is_the_ramped_matrix_products(
    rng: np.random.Generator, moved: bool, add: bool
) -> None:
    carriers = np.sin(rng.uniform(0, 2 * np.pi, (FRAMES, CONTACTS)))
    starts = rng.uniform(0.0, 0.3, (CONTACTS, CHANNELS))
    targets = starts + rng.uniform(-0.1, 0.1, starts.shape) if moved else starts.copy()
    ramp = np.arange(1, FRAMES + 1) / FRAMES
    before = rng.uniform(-0.2, 0.2, (FRAMES, CHANNELS)).astype(np.float32)
    out = before.copy() if add else np.full_like(before, np.nan)
    assert kernels.add_contacts(out, carriers, starts, targets, ramp, moved, add)
    expected = carriers @ starts + ramp[:, None] * (carriers @ (targets - starts))
    if add:
        expected = expected + before
    np.testing.assert_allclose(out, expected.astype(np.float32), rtol=1e-6, atol=1e-7)


def test_the_contacts_sum_says_when_a_sample_is_not_finite(rng: np.random.Generator) -> None:
    carriers = rng.standard_normal((FRAMES, CONTACTS))
    carriers[40, 2] = np.inf
    starts = np.full((CONTACTS, CHANNELS), 0.1)
    out = np.zeros((FRAMES, CHANNELS), dtype=np.float32)
    ramp = np.arange(1, FRAMES + 1) / FRAMES
    assert not kernels.add_contacts(out, carriers, starts, starts, ramp, False, True)


def plain_pass(blocker: DcBlocker, block: np.ndarray, threshold: float = 0.9) -> float:
    levels = np.zeros(CHANNELS, dtype=np.float32)
    calibration = np.linspace(0.8, 1.2, CHANNELS).astype(np.float32)
    return blocker.plain_pass(block, levels, calibration, True, threshold)


@pytest.mark.parametrize("kind", ["nan", "inf", "past the dead band", "over the threshold"])
def test_a_block_that_is_not_plain_is_left_as_it_was(rng: np.random.Generator, kind: str) -> None:
    blocker = DcBlocker(CHANNELS, 48_000, 1.0)
    t = np.arange(FRAMES)[:, None] / 48_000
    block = (0.3 * np.sin(2 * np.pi * 200.0 * t) * np.ones(CHANNELS)).astype(np.float32)
    assert plain_pass(blocker, block.copy()) > 0.0  # the state moves: not all zeros
    state = blocker._state.copy()
    if kind == "nan":
        block[7, 3] = np.nan
    elif kind == "inf":
        block[7, 3] = -np.inf
    elif kind == "past the dead band":
        blocker._state[0, 2] = 0.06
        state = blocker._state.copy()
    else:
        block *= 3.5
    kept = block.copy()
    assert plain_pass(blocker, block) == -1.0
    np.testing.assert_array_equal(block.view(np.uint32), kept.view(np.uint32))
    np.testing.assert_array_equal(blocker._state, state)


def test_a_plain_block_is_calibrated_and_metered(rng: np.random.Generator) -> None:
    blocker = DcBlocker(CHANNELS, 48_000, 1.0)
    block = rng.uniform(-0.5, 0.5, (FRAMES, CHANNELS)).astype(np.float32)
    calibration = np.linspace(0.8, 1.2, CHANNELS).astype(np.float32)
    expected = block * calibration
    levels = np.zeros(CHANNELS, dtype=np.float32)
    loudest = blocker.plain_pass(block, levels, calibration, True, 0.9)
    np.testing.assert_array_equal(block, expected)
    np.testing.assert_array_equal(levels, np.abs(block).max(axis=0))
    assert loudest == float(levels.max())
