"""Streaming FIR filtering of several channels by uniformly partitioned FFT convolution.

A calibration FIR has up to 4096 taps; in direct form that is 4096 multiply-adds per
sample and channel. Here the taps are cut into partitions of ``partition_frames`` taps
and the input into partitions of as many frames, aligned to frame 0 (Wefers, "Partitioned
convolution algorithms for real-time auralization", 2015, ch. 5; the frequency-domain
delay line of uniformly partitioned overlap-save). The output of input partition ``j`` is

- the *past*: everything partitions ``j - 1, j - 2, ...`` contribute, computed once by
  FFT when partition ``j - 1`` is complete (overlap-save, the partition ``j - 1`` followed
  by zeros for the first taps, whole earlier partition pairs for the others);
- the *present*: partition ``j`` itself through the first ``partition_frames`` taps,
  a lower-triangular Toeplitz matrix times the frames received so far (zero beyond).

There is no latency: a block of any size gets its output at once. Row ``r`` of the
triangular product only multiplies frames ``0..r`` of the partition by non-zero taps, and
the product always has the same shape, so a frame's output does not depend on how the
input was cut into blocks: block-wise equals whole, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

PARTITION_FRAMES = 128
"""Partition length: about the cost optimum for 4096 taps (the present costs
``partition_frames`` multiply-adds per sample, the past ``4 * taps / partition_frames``
real operations in the spectrum plus two FFTs of ``2 * partition_frames`` per partition)."""


class PartitionedFir:
    """Filter ``channels`` signals, each with its own taps, block after block.

    Parameters
    ----------
    taps : sequence of sequences of float, one per channel, each non-empty
        Shorter rows are zero-padded to the longest.
    partition_frames : int, >= 1

    Notes
    -----
    The present and the FFTs run in float64, the sum over partitions in complex64; the
    output agrees with a float64 direct form to about 1e-8 of full scale (4096 taps).
    """

    def __init__(
        self, taps: Sequence[Sequence[float]], *, partition_frames: int = PARTITION_FRAMES
    ) -> None:
        rows = [np.asarray(t, dtype=np.float64).ravel() for t in taps]
        size = partition_frames
        longest = max(len(r) for r in rows)
        parts = max(1, -(-longest // size))
        padded = np.zeros((len(rows), parts * size))
        for ch, row in enumerate(rows):
            padded[ch, : len(row)] = row
        self.channels = len(rows)
        self.partition_frames = size
        by_part = padded.reshape(self.channels, parts, size).transpose(1, 0, 2)  # (K, C, P)
        # The present: y[r] = sum_{i <= r} h[r - i] x[i], one lower-triangular matrix per channel.
        lag = np.arange(size)[:, None] - np.arange(size)[None, :]
        self._present = np.ascontiguousarray(
            np.where(lag >= 0, by_part[0][:, np.clip(lag, 0, None)], 0.0)
        )
        # The past: tap 0 reaches no earlier partition, so it is left out (exact zeros for
        # an identity filter instead of rounding noise).
        first = by_part[0].copy()
        first[:, 0] = 0.0
        spectra = np.fft.rfft(np.concatenate([by_part, np.zeros_like(by_part)], axis=2), axis=2)
        self._first = np.fft.rfft(np.concatenate([first, np.zeros_like(first)], axis=1), axis=1)
        older = parts - 1  # partition pairs kept: X_{j-1} .. X_{j-K+1}
        self._older = older
        # H_{K-1} .. H_1, oldest first, in complex64: the sum over partitions is the
        # bulk of the work and its rounding (about 1e-8 of full scale) stays far below 1e-6.
        self._later = np.ascontiguousarray(spectra[1:][::-1], dtype=np.complex64)
        self._delay_line = np.zeros(
            (2 * max(older, 1), self.channels, size + 1), dtype=np.complex64
        )
        self._products = np.empty_like(self._later)
        self._slot = 0
        self._previous_head = np.zeros((self.channels, size + 1), dtype=complex)
        self._alternate = np.where(np.arange(size + 1) % 2 == 0, 1.0, -1.0)
        self._current = np.zeros((self.channels, size))
        self._fill = 0
        self._past = np.zeros((self.channels, size))
        self._pair = np.zeros((self.channels, 2 * size))
        self._output = np.empty((self.channels, size, 1))

    def process(self, block: np.ndarray) -> None:
        """Filter ``block`` in place, shape (frames, channels), float32 or float64."""
        start = 0
        frames = block.shape[0]
        size = self.partition_frames
        while start < frames:
            n = min(frames - start, size - self._fill)
            lo, hi = self._fill, self._fill + n
            self._current[:, lo:hi] = block[start : start + n].T
            np.matmul(self._present, self._current[:, :, None], out=self._output)
            out = self._output[:, lo:hi, 0]
            out += self._past[:, lo:hi]
            out += 0.0  # -0.0 to +0.0, whatever the frames past ``hi`` held
            block[start : start + n] = out.T
            start += n
            self._fill = hi
            if self._fill == size:
                self._advance()

    def _advance(self) -> None:
        """Partition ``j - 1`` is complete: compute the past of partition ``j``."""
        size = self.partition_frames
        pair = self._pair
        pair[:, :size] = self._current
        # rfft([x_{j-1}, 0]); shifting by half the length negates the odd bins, so the
        # pair's spectrum rfft([x_{j-2}, x_{j-1}]) is the previous head plus this one so.
        head = np.fft.rfft(pair, axis=1)
        acc = self._first * head
        if self._older:
            k = self._older
            line = self._delay_line
            whole = self._previous_head + head * self._alternate
            self._previous_head = head
            line[self._slot] = whole
            line[self._slot + k] = whole
            self._slot = (self._slot + 1) % k
            window = line[self._slot : self._slot + k]
            np.multiply(self._later, window, out=self._products)
            acc += self._products.sum(axis=0)
        self._past = np.fft.irfft(acc, n=2 * size, axis=1)[:, size:]
        self._current[:] = 0.0
        self._fill = 0
