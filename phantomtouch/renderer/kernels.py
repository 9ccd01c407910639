"""Compiled loops for the audio callback's fixed chain: the contacts' sum, and the
output chain's pass over a plain block.

A block the voices mix is nearly always plain: finite, within the DC blocker's dead band
and, once calibrated, within the limiter's threshold. All the chain does to it is advance
the DC blocker's state in closed form, calibrate it and meter it. As numpy calls, that
and the contacts' sum are a dozen or more distinct operations, and the callback pays for
each distinct one again when its core wakes from idle between periods (``docs/engine.md``,
Where to measure). Here each is one compiled loop.

numba compiles them in nopython mode for one signature each (arrays of any layout) when
this module is first imported, outside the callback (the DC blocker and the contacts' mix
import it as they are built), and calls each once there, so that the first call a callback
makes costs what later ones do. The machine code is cached on disk beside this module, or
in the user's cache folder where that is not writable, so later processes load it
instead of compiling it. With a signature given, a call with other types raises
TypeError instead of compiling in the callback. Without ``fastmath``, each sample is
computed with the float32 and float64 operations of the numpy code it stands for, in the
same order; a sum over contacts or frames adds its terms one by one, in order.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit("void(float64[:], float64[:], float64, float32[:, :], float64)", cache=True)
def advance_dc(
    state: np.ndarray, weights: np.ndarray, decay: float, block: np.ndarray, peak: float
) -> None:
    """Advance the DC blocker's state over ``block`` in closed form, in place.

    Parameters
    ----------
    state : ndarray, shape (channels,), float64
        ``z`` per channel (:class:`~phantomtouch.renderer.dc_blocker.DcBlocker`).
    weights : ndarray, shape (frames,), float64
        ``r w`` for a block of ``frames``.
    decay : float
        ``r**frames``.
    block : ndarray, shape (frames, channels), float32
    peak : float
        The block's largest absolute sample: 0 leaves the weighted sum out.
    """
    frames, channels = block.shape
    for channel in range(channels):
        z = state[channel] * decay
        if peak != 0.0:
            total = 0.0
            for k in range(frames):
                total += weights[k] * block[k, channel]
            z += total
        state[channel] = z


@numba.njit(
    "float64(float32[:, :], float32[:], float64[:], float64[:], float64, float64, float64,"
    " float64, float32[:], boolean, float64)",
    cache=True,
)
def plain_pass(
    block: np.ndarray,
    levels: np.ndarray,
    state: np.ndarray,
    weights: np.ndarray,
    decay: float,
    reach: float,
    pole: float,
    dead_band: float,
    calibration: np.ndarray,
    calibrate: bool,
    threshold: float,
) -> float:
    """The output chain's pass over a plain block, or nothing when it is not plain.

    A block is plain when every sample is finite, the DC blocker's bound over it stays
    within its dead band, and its calibrated peaks are within ``threshold``. Then the DC
    state advances in closed form (:func:`advance_dc`), the block is calibrated in place
    when ``calibrate``, ``levels`` holds its calibrated peaks, and the largest of them is
    returned. Otherwise -1.0 is returned and only ``levels`` was written.

    Parameters
    ----------
    block : ndarray, shape (frames, channels), float32
    levels : ndarray, shape (channels,), float32
        Written: the peaks (calibrated when the block is plain).
    state, weights, decay
        As for :func:`advance_dc`.
    reach : float
        ``(1 - r) frames``: how far the block may move the tracked offset per unit peak.
    pole : float
        ``r``.
    dead_band : float
        The DC blocker's dead band, in full scale.
    calibration : ndarray, shape (channels,), float32
        The calibration's gain per channel.
    calibrate : bool
        The output stage calibrates (some gain is not 1).
    threshold : float
        The largest calibrated peak a plain block may have.
    """
    frames, channels = block.shape
    for channel in range(channels):
        levels[channel] = 0.0
    for k in range(frames):
        for channel in range(channels):
            magnitude = abs(block[k, channel])
            if magnitude > levels[channel]:
                levels[channel] = magnitude
            elif magnitude != magnitude:
                return -1.0
    peak = 0.0
    for channel in range(channels):
        peak = max(peak, levels[channel])
    offset = 0.0
    for channel in range(channels):
        offset = max(offset, abs(state[channel]))
    if not offset / pole + reach * peak <= dead_band:
        return -1.0
    loudest = 0.0
    for channel in range(channels):
        levels[channel] *= calibration[channel]
        loudest = max(loudest, levels[channel])
    if not loudest <= threshold:
        return -1.0
    advance_dc(state, weights, decay, block, peak)
    if calibrate:
        for k in range(frames):
            for channel in range(channels):
                block[k, channel] *= calibration[channel]
    return loudest


@numba.njit(
    "boolean(float32[:, :], float64[:, :], float64[:, ::1], float64[:, ::1], float64[::1],"
    " boolean, boolean)",
    cache=True,
)
def add_contacts(
    out: np.ndarray,
    carriers: np.ndarray,
    starts: np.ndarray,
    targets: np.ndarray,
    ramp: np.ndarray,
    moved: bool,
    add: bool,
) -> bool:
    """The contacts' sum, each contact's gains ramped linearly across the block, into
    ``out``: ``carriers @ starts + ramp * (carriers @ (targets - starts))`` per frame, in
    float64, added to ``out`` when ``add`` (else written), rounded once to float32. True
    when every sample of ``out`` is finite after it.

    Parameters
    ----------
    out : ndarray, shape (frames, channels), float32
    carriers : ndarray, shape (frames, contacts), float64
    starts, targets : ndarray, shape (contacts, channels), float64, C order
        Each contact's gains where the last block ended, and where they ramp to (its
        gains again when it stays put).
    ramp : ndarray, shape (frames,), float64
        ``(k + 1) / frames``.
    moved : bool
        Some target is not its start (else the ramped sum is left out).
    add : bool
    """
    frames, channels = out.shape
    contacts = carriers.shape[1]
    total = np.empty(channels)
    ramped = np.empty(channels)
    deltas = np.empty((contacts, channels))
    for j in range(contacts):
        for channel in range(channels):
            deltas[j, channel] = targets[j, channel] - starts[j, channel]
    finite = True
    for k in range(frames):
        total[:] = 0.0
        for j in range(contacts):
            carrier = carriers[k, j]
            for channel in range(channels):
                total[channel] += carrier * starts[j, channel]
        if moved:
            ramped[:] = 0.0
            for j in range(contacts):
                carrier = carriers[k, j]
                for channel in range(channels):
                    ramped[channel] += carrier * deltas[j, channel]
            for channel in range(channels):
                total[channel] += ramped[channel] * ramp[k]
        for channel in range(channels):
            if add:
                out[k, channel] = out[k, channel] + total[channel]
            else:
                out[k, channel] = total[channel]
            finite = finite and math.isfinite(out[k, channel])
    return finite


def _warm() -> None:
    """Call each loop once on a small block: the first call of a loop in a process sets up
    what its later calls reuse (about a millisecond), so it is made here, at the import,
    and never by the callback."""
    block = np.zeros((4, 2), dtype=np.float32)
    levels = np.zeros(2, dtype=np.float32)
    state, gains = np.zeros(2), np.zeros((1, 2))
    weights, ramp = np.zeros(4), np.zeros(4)
    advance_dc(state, weights, 1.0, block, 0.0)
    plain_pass(block, levels, state, weights, 1.0, 0.0, 1.0, 1.0, levels, False, 1.0)
    add_contacts(block, np.zeros((4, 1)), gains, gains, ramp, False, True)


_warm()
