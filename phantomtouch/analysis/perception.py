"""Where and how strongly the phantom is felt, from the actuators' accelerations.

A deliberately simple model of the funnelling illusion: over a short window (default
40 ms; the window length is an assumption of the model, not a measured integration
time), the phantom sits at the energy-weighted centroid of the actuator positions,

    p = sum_i E_i p_i / sum_i E_i,    E_i = mean over the window of a_i(t)^2,

and is felt with the summed energy, ``level_db = 10 log10(sum_i E_i / (1 µm/s²)^2)``.
With the power law the energies are the barycentric weights, so a render without
errors puts the centroid exactly on the intended point and keeps the summed energy
constant; every deviation measured here comes from how the signals were made.

The default window spans whole periods of the paper's carriers (2, 4 and 6 periods
of 50, 100 and 150 Hz), so a steady sine gives a ripple-free energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phantomtouch.analysis.twin import MICRO_M_S2
from phantomtouch.errors import ParameterError
from phantomtouch.schema.device import DeviceProfile

DEFAULT_WINDOW_S = 0.040
DEFAULT_HOP_S = 0.005


@dataclass(frozen=True)
class Percept:
    """The perceived phantom over time.

    Attributes
    ----------
    times_s : ndarray, shape (n,)
        Centre of each window, s from the first frame.
    positions_cm : ndarray, shape (n, 2)
        Energy centroid (x_cm, y_cm); NaN in silent windows.
    level_db : ndarray, shape (n,)
        Summed energy as a level, dB re 1 µm/s²; -inf in silent windows.
    window_frames, hop_frames : int
    """

    times_s: np.ndarray
    positions_cm: np.ndarray
    level_db: np.ndarray
    window_frames: int
    hop_frames: int


def window_starts(frames: int, window_frames: int, hop_frames: int) -> np.ndarray:
    """First frame of every full window, shape (n,), int64."""
    if frames < window_frames:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, frames - window_frames + 1, hop_frames, dtype=np.int64)


def windowed_mean(values: np.ndarray, window_frames: int, hop_frames: int) -> np.ndarray:
    """Mean of ``values`` (frames, ...) over each window of :func:`window_starts`.

    Sums hop-long chunks first and slides over whole chunks, so long signals lose no
    precision to a running sum (the window must be a multiple of the hop).
    """
    values = np.asarray(values, dtype=np.float64)
    per = window_frames // hop_frames
    chunks = len(values) // hop_frames
    sums = values[: chunks * hop_frames].reshape(chunks, hop_frames, *values.shape[1:]).sum(1)
    n = len(window_starts(len(values), window_frames, hop_frames))
    out = np.zeros((n, *values.shape[1:]))
    for k in range(per):
        out += sums[k : k + n]
    return out / window_frames


def _frames(value_s: float, sample_rate_hz: int, name: str) -> int:
    frames = round(value_s * sample_rate_hz)
    if not (np.isfinite(value_s) and frames >= 1):
        raise ParameterError(f"{name}={value_s!r} must be at least one frame long")
    return frames


def perceive(
    accelerations: np.ndarray,
    device: DeviceProfile,
    *,
    sample_rate_hz: int | None = None,
    window_s: float = DEFAULT_WINDOW_S,
    hop_s: float = DEFAULT_HOP_S,
) -> Percept:
    """The perceived phantom position and level over time.

    Parameters
    ----------
    accelerations : ndarray, shape (frames, channels)
        Acceleration of each output channel's actuator, m/s² (e.g. from
        :class:`~phantomtouch.analysis.twin.ArmbandTwin`).
    device : DeviceProfile
        Which actuator sits where and on which channel.
    sample_rate_hz : int or None
        None: the device's rate.
    window_s : float, > 0
        Integration window; rounded to a whole number of hops.
    hop_s : float, > 0, <= window_s
        Distance between window starts.

    Returns
    -------
    Percept
    """
    rate = int(sample_rate_hz or device.sample_rate_hz)
    accelerations = np.asarray(accelerations)
    if accelerations.ndim != 2 or accelerations.shape[1] < device.channels:
        raise ParameterError(
            f"accelerations has shape {accelerations.shape}; expected (frames, {device.channels})"
        )
    hop = _frames(hop_s, rate, "hop_s")
    window = _frames(window_s, rate, "window_s")
    if window < hop:
        raise ParameterError(f"window_s={window_s!r} must be at least hop_s={hop_s!r}")
    window = hop * round(window / hop)
    columns = [a.channel - 1 for a in device.actuators]
    energy = windowed_mean(accelerations[:, columns] ** 2, window, hop)  # (n, actuators)
    total = energy.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        positions = energy @ device.positions_cm() / total[:, None]
        level_db = 10.0 * np.log10(total / MICRO_M_S2**2)
    positions[~(total > 0.0)] = np.nan
    starts = window_starts(len(accelerations), window, hop)
    return Percept(
        times_s=(starts + (window - 1) / 2.0) / rate,
        positions_cm=positions,
        level_db=level_db,
        window_frames=window,
        hop_frames=hop,
    )
