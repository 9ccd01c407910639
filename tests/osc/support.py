"""A VRChat-like sender: contact receivers on the armband and a hand that slides over them."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from pythonosc.udp_client import SimpleUDPClient

from phantomtouch.engine import EngineFront
from phantomtouch.osc.mapping import ReceiverMap
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, policy_table
from phantomtouch.service.settings import Settings


def osc_admission(engine: EngineFront) -> Admission:
    """The admission a bridge over ``engine`` alone opens its senders at: the service's
    default policy table, no pattern library."""
    return Admission(engine, policy_table(Settings()))


FRAME_S = 1.0 / 90.0
"""VRChat's frame at 90 Hz."""
RADIUS_CM = 6.0
"""Radius of each receiver's sphere: larger than the row spacing (4.8 cm), so that a
hand between two rows is inside both."""


def proximity(map_: ReceiverMap, x_cm: float, y_cm: float, depth_cm: float) -> np.ndarray:
    """What VRChat's receivers in proximity mode report: 1 at the centre, 0 at the radius."""
    positions = np.array([(r.x_cm, r.y_cm) for r in map_.receiver])
    distance = np.sqrt((positions[:, 0] - x_cm) ** 2 + (positions[:, 1] - y_cm) ** 2 + depth_cm**2)
    return np.clip(1.0 - distance / RADIUS_CM, 0.0, 1.0)


def send_stream(
    client: SimpleUDPClient,
    map_: ReceiverMap,
    hand: Callable[[float], tuple[float, float, float]],
    duration_s: float,
    *,
    on_frame: Callable[[int], None] | None = None,
) -> None:
    """Send the receivers' values at 90 Hz for ``duration_s``, each only when it changed
    (as VRChat does). ``hand(t_s)`` is (x_cm, y_cm, depth_cm)."""
    frames = round(duration_s / FRAME_S)
    last = np.full(len(map_.receiver), -1.0)
    start = time.perf_counter()
    for k in range(frames):
        values = proximity(map_, *hand(k * FRAME_S))
        for receiver, value, before in zip(map_.receiver, values, last, strict=True):
            if value != before:
                client.send_message(receiver.address, float(value))
        last = values
        if on_frame is not None:
            on_frame(k)
        delay_s = start + (k + 1) * FRAME_S - time.perf_counter()
        if delay_s > 0:
            time.sleep(delay_s)


def energy_track(
    recording: np.ndarray, device: DeviceProfile, window_frames: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per window: summed energy and the energy centroid ``sum(E_c p_c) / sum(E_c)``, cm.

    With the power law the energy centroid of the gains is exactly the rendered point
    (docs/algorithms.md, sec. 4), so it is where the phantom is.
    """
    windows = len(recording) // window_frames
    blocks = recording[: windows * window_frames].reshape(windows, window_frames, -1)
    energy = (blocks.astype(np.float64) ** 2).sum(axis=1)  # (windows, channels)
    positions = np.zeros((energy.shape[1], 2))
    for actuator in device.actuators:
        positions[actuator.channel - 1] = (actuator.x_cm, actuator.y_cm)
    total = energy.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        centroid = (energy @ positions) / total[:, None]
    return total, centroid
