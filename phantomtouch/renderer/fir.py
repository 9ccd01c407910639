"""Streaming FIR filtering of several channels by uniformly partitioned FFT convolution.

A calibration FIR has up to 4096 taps; in direct form that is 4096 multiply-adds per
sample and channel. Here the input is cut into partitions of ``partition_frames`` frames,
aligned to frame 0, and the output of input partition ``j`` is the sum of

- the *present*: partition ``j`` itself through the first ``partition_frames`` taps,
  a lower-triangular Toeplitz matrix times the frames received so far (zero beyond);
- the *past*: what partitions ``j - 1, j - 2, ...`` contribute, computed once when
  partition ``j - 1`` is complete, from a frequency-domain delay line (Wefers,
  "Partitioned convolution algorithms for real-time auralization", 2015, ch. 5).

The past uses one spectrum per input partition, ``X_m`` = the DFT of length ``2 P``
(``P = partition_frames``) of partition ``m`` followed by ``P`` zeros, and one per tap
segment, ``H_d`` = the DFT of taps ``(d - 1) P .. (d + 1) P - 1``. Partition ``m = j - d``
meets the output frames of partition ``j`` only through segment ``d``, and the linear
convolution of ``P`` frames with ``2 P`` taps puts exactly those frames, unaliased, in the
second half of the circular one. So the past of partition ``j`` is the second half of the
inverse DFT of ``sum_d H_d X_{j - d}``: one forward DFT, one multiply-accumulate over the
delay line and one inverse DFT per partition, whatever the number of taps.

The DFTs are matrix products (interleaved real and imaginary parts): eight channels at
once make them small matrix-matrix products, cheaper at ``P = 128`` than eight FFTs of 256
points, and the inverse computes only the half it keeps. Everything runs in float32 and
complex64. The discarded half of segment 1 holds partition ``j - 1`` through the first
taps, the bulk of the signal, and its rounding would reach the kept half; so the first
``TAIL_FRAMES`` taps are left out of segment 1 and their reach from partition ``j - 1``
into partition ``j`` (an upper-triangular Toeplitz matrix times the last frames of
``j - 1``) is added in the time domain. The output then agrees with a float64 direct
form to about 2e-7 of full scale.

There is no latency: a block of any size gets its output at once. Row ``r`` of the
triangular product only multiplies frames ``0..r`` of the partition by non-zero taps, each
half of its rows is always computed as the same product (the first half over the first
half of the frames, the second over all), and the past depends only on complete partitions, so a
frame's output does not depend on how the input was cut into blocks: block-wise equals
whole, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

PARTITION_FRAMES = 128
"""Partition length, the cost optimum for 4096 taps in blocks of 128 to 65536 frames.

Per frame and channel the present costs ``3 P / 4`` multiply-adds, the DFTs about
``4 P``, and the delay line ``taps / P`` complex multiply-adds: 64 doubles the delay
line's share, 256 the rest (measured in 128-frame blocks: 1.3x and 3.8x the time)."""


TAIL_FRAMES = 32
"""Taps below this many reach the next partition in the time domain (module notes): the
largest error, short filters at twice full scale, drops from 8e-7 to 2e-7 of full scale
for under a tenth more time."""


def _forward_dft(size: int) -> np.ndarray:
    """(size, 2 (size + 1)) float32: frames -> interleaved rfft of length ``2 size``."""
    angle = np.pi * np.outer(np.arange(size), np.arange(size + 1)) / size
    matrix = np.empty((size, 2 * (size + 1)))
    matrix[:, 0::2] = np.cos(angle)
    matrix[:, 1::2] = -np.sin(angle)
    return matrix.astype(np.float32)


def _inverse_dft_second_half(size: int) -> np.ndarray:
    """(2 (size + 1), size) float32: interleaved rfft -> frames ``size..2 size - 1`` of irfft."""
    angle = np.pi * np.outer(np.arange(size + 1), np.arange(size, 2 * size)) / size
    weight = np.full(size + 1, 2.0 / (2 * size))
    weight[[0, -1]] = 1.0 / (2 * size)  # DC and Nyquist appear once in the spectrum
    matrix = np.empty((2 * (size + 1), size))
    matrix[0::2] = weight[:, None] * np.cos(angle)
    matrix[1::2] = -weight[:, None] * np.sin(angle)
    matrix[[1, -1]] = 0.0  # the imaginary parts of DC and Nyquist do not exist
    return matrix.astype(np.float32)


class PartitionedFir:
    """Filter ``channels`` signals, each with its own taps, block after block.

    Parameters
    ----------
    taps : sequence of sequences of float, or array of shape (channels, taps)
        One row per channel, each non-empty; shorter rows are zero-padded to the longest.
    partition_frames : int, >= 1
    """

    def __init__(
        self,
        taps: Sequence[Sequence[float]] | np.ndarray,
        *,
        partition_frames: int = PARTITION_FRAMES,
    ) -> None:
        rows = [np.asarray(t, dtype=np.float64).ravel() for t in taps]
        size = partition_frames
        parts = max(1, -(-max(len(r) for r in rows) // size))
        padded = np.zeros((len(rows), (parts + 1) * size))
        for ch, row in enumerate(rows):
            padded[ch, : len(row)] = row
        self.channels = len(rows)
        self.partition_frames = size
        # The present: y[r] = sum_{i <= r} h[r - i] x[i], one lower-triangular matrix per channel.
        lag = np.arange(size)[:, None] - np.arange(size)[None, :]
        present = np.where(lag >= 0, padded[:, np.clip(lag, 0, None)], 0.0).astype(np.float32)
        # Rows of the first half are zero beyond it: they multiply only the first half.
        half = size // 2
        self._half = half
        self._present_top = np.ascontiguousarray(present[:, :half, :half])
        self._present_bottom = np.ascontiguousarray(present[:, half:, :])
        tail = min(TAIL_FRAMES, size)
        # The tail: y[r] += sum_{i > r} h[Q + r - i] x'[i], x' the last Q frames of j - 1,
        # for the first Q = ``tail`` rows of partition j.
        lag = np.arange(tail)[:, None] - np.arange(tail)[None, :]
        self._tail = np.ascontiguousarray(
            np.where(lag < 0, padded[:, np.clip(tail + lag, 0, None)], 0.0), dtype=np.float32
        )
        self._tail_output = np.empty((self.channels, tail, 1), dtype=np.float32)
        # The past: segment d covers taps (d - 1) P .. (d + 1) P - 1, segments 1..K; taps
        # below Q reach partition j - 1 by the tail and partition j by the present.
        segments = padded[:, np.arange(parts)[:, None] * size + np.arange(2 * size)]
        segments[:, 0, :tail] = 0.0
        spectra = np.fft.rfft(segments, axis=2).transpose(1, 0, 2)  # (K, C, P + 1)
        self._parts = parts
        self._segments = np.ascontiguousarray(spectra[::-1], dtype=np.complex64)  # H_K..H_1
        self._forward = _forward_dft(size)
        self._inverse = _inverse_dft_second_half(size)
        self._ones = np.ones(parts, dtype=np.float32)
        # X_{j-1} .. X_{j-K} in a ring; the newest is at ``_slot - 1``.
        self._line = np.zeros((parts, self.channels, size + 1), dtype=np.complex64)
        self._slot = 0
        self._products = np.empty_like(self._segments)
        self._sum = np.empty((self.channels, 2 * (size + 1)), dtype=np.float32)
        self._current = np.zeros((self.channels, size), dtype=np.float32)
        self._fill = 0
        self._past = np.zeros((self.channels, size), dtype=np.float32)
        self._output = np.empty((self.channels, size, 1), dtype=np.float32)
        # Views, made once: the callback pays for no slicing it can avoid.
        self._column = self._current[:, :, None]
        self._top_column = self._current[:, :half, None]
        self._top_output = self._output[:, :half]
        self._bottom_output = self._output[:, half:]
        self._tail_input = self._current[:, size - tail :, None]
        self._tail_rows = (self._past[:, :tail], self._tail_output[:, :, 0])
        self._terms = self._products.view(np.float32).reshape(parts, -1)
        self._sum_flat = self._sum.reshape(-1)
        self._steps = [self._step(slot) for slot in range(parts)]

    def _step(self, slot: int) -> tuple[np.ndarray, tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """For a new spectrum at ``slot``: where it goes, and the delay line oldest first
        (X_{j-K} .. X_{j-1} against H_K .. H_1) as two contiguous runs of the ring."""
        oldest = slot + 1
        older = self._parts - oldest
        segments, line, products = self._segments, self._line, self._products
        return (
            line[slot].view(np.float32),
            (segments[:older], line[oldest:], products[:older]),
            (segments[older:], line[:oldest], products[older:]),
        )

    def process(self, block: np.ndarray) -> None:
        """Filter ``block`` in place, shape (frames, channels), float32.

        A float64 block is filtered in float32 precision.
        """
        start = 0
        frames = block.shape[0]
        size = self.partition_frames
        current = self._current
        while start < frames:
            lo = self._fill
            n = min(frames - start, size - lo)
            hi = lo + n
            current[:, lo:hi] = block[start : start + n].T
            if lo < self._half:
                np.matmul(self._present_top, self._top_column, out=self._top_output)
            if hi > self._half:
                np.matmul(self._present_bottom, self._column, out=self._bottom_output)
            # The past holds no -0.0, so a present of -0.0 or +0.0 (the sign of zero
            # products with frames past ``hi``) gives +0.0 either way.
            np.add(self._output[:, lo:hi, 0], self._past[:, lo:hi], out=block[start : start + n].T)
            start += n
            self._fill = hi
            if hi == size:
                self._advance()

    def _advance(self) -> None:
        """Partition ``j - 1`` is complete: compute the past of partition ``j``."""
        spectrum, older, newer = self._steps[self._slot]
        np.matmul(self._current, self._forward, out=spectrum)
        np.multiply(older[0], older[1], out=older[2])
        np.multiply(newer[0], newer[1], out=newer[2])
        np.matmul(self._ones, self._terms, out=self._sum_flat)
        np.matmul(self._sum, self._inverse, out=self._past)
        np.matmul(self._tail, self._tail_input, out=self._tail_output)
        rows, tail = self._tail_rows
        np.add(rows, tail, out=rows)
        self._past += 0.0  # -0.0 to +0.0
        self._slot = (self._slot + 1) % self._parts
        self._current[:] = 0.0
        self._fill = 0
