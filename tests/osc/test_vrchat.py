"""A VRChat-like stream over real UDP drives a real engine; its captured output is read back.

A hand approaches the middle of the armband at the elbow end, slides towards the wrist
at 4.8 cm/s, and lifts off, while eight contact receivers (one per actuator, the default
map) report their proximity at 90 Hz. The engine renders into a capture sink at real-time
pace; the energy centroid of what it rendered must follow the hand.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from phantomtouch.engine import Engine
from phantomtouch.osc.bridge import OscBridge
from phantomtouch.osc.mapping import ReceiverMap, default_map
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile
from tests.osc.support import FRAME_S, energy_track, osc_admission, proximity, send_stream
from tests.support.yardstick import WakeUpLag

DEVICE = DeviceProfile.default()
START_Y_CM, END_Y_CM = 12.0, 2.4
X_CM = 1.9
APPROACH_S, SLIDE_S, LIFT_S = 0.3, 2.0, 0.3


def hand(t_s: float) -> tuple[float, float, float]:
    """(x_cm, y_cm, depth_cm): approach from 6 cm above to 1 cm, slide, lift again."""
    if t_s < APPROACH_S:
        return X_CM, START_Y_CM, 6.0 - 5.0 * t_s / APPROACH_S
    t_s -= APPROACH_S
    if t_s < SLIDE_S:
        return X_CM, START_Y_CM + (END_Y_CM - START_Y_CM) * t_s / SLIDE_S, 1.0
    t_s -= SLIDE_S
    return X_CM, END_Y_CM, 1.0 + 5.0 * min(1.0, t_s / LIFT_S)


@pytest.fixture
def engine() -> Iterator[tuple[Engine, CaptureSink]]:
    sink = CaptureSink(DEVICE, realtime=True)
    with Engine(DEVICE, sink) as engine:
        yield engine, sink


def _map(watchdog_s: float = 1.0) -> ReceiverMap:
    return default_map(DEVICE).model_copy(update={"watchdog_s": watchdog_s})


def test_the_phantom_follows_a_hand_sliding_over_the_receivers(engine) -> None:
    eng, sink = engine
    receivers = _map()
    sent_frames: list[int] = []
    with OscBridge(osc_admission(eng), receivers, port=0) as bridge, WakeUpLag() as lag:
        client = SimpleUDPClient(*bridge.address)
        send_stream(
            client,
            receivers,
            hand,
            APPROACH_S + SLIDE_S + LIFT_S,
            on_frame=lambda k: sent_frames.append(eng.now_frames),
        )
        # The release ramp, in the engine's time (its clock may lag on a busy machine).
        deadline = time.monotonic() + 5.0
        while eng.now_frames < sent_frames[-1] + 0.3 * DEVICE.sample_rate_hz:
            assert time.monotonic() < deadline, "the engine's clock stalled"
            time.sleep(0.02)
        assert bridge.contacts == []  # every receiver fell to 0: released
        counts = bridge.counters.snapshot()
    assert counts["accepted"] > 0
    assert bridge.counters.dropped == 0, counts

    window = round(FRAME_S * DEVICE.sample_rate_hz)
    energy, centroid = energy_track(sink.recording(), DEVICE, window)
    # Where the hand was in each window: the frame each 90 Hz frame was sent at.
    sent = np.array(sent_frames)
    frame_of = np.arange(len(energy)) * window + window // 2
    k = np.clip(np.searchsorted(sent, frame_of) - 1, 0, None)
    sliding = (
        (frame_of > sent[0])
        & (k * FRAME_S > APPROACH_S + 0.05)
        & (k * FRAME_S < APPROACH_S + SLIDE_S - 0.05)
    )
    # Of 171 windows in 1.9 s, fewer where the engine's clock lagged: its pacer drops the
    # time it was woken late by, as much as a thread of this process lost meanwhile.
    assert sliding.sum() > 100 * lag.on_time_fraction, (sliding.sum(), lag.on_time_fraction)

    # Continuous: the phantom never jumps, and the level never drops out while sliding.
    positions = np.array([(r.x_cm, r.y_cm) for r in receivers.receiver])

    def weighted_y(frame: int) -> float:
        p = proximity(receivers, *hand(frame * FRAME_S))
        return float(p @ positions[:, 1] / p.sum())

    y = centroid[sliding, 1]
    step_cm = np.abs(np.diff(y))
    hand_step_cm = abs(END_Y_CM - START_Y_CM) / SLIDE_S * FRAME_S  # 0.053 cm per frame
    # A window moves at most as far as the values sent over the last nine windows (100 ms)
    # moved the weighted mean, plus a little: one frame's worth when all runs on time,
    # more where the sender, or the bridge on a busy machine, was late and caught up
    # (latest wins, as for the WebSocket's moves).
    sent_y = np.array([weighted_y(i) for i in k[sliding]])
    sent_step_cm = np.abs(sent_y[1:] - sent_y[np.maximum(np.arange(1, len(sent_y)) - 9, 0)])
    assert (step_cm <= sent_step_cm + 2 * hand_step_cm).all(), step_cm.max()
    level_db = 10 * np.log10(energy[sliding] / np.median(energy[sliding]))
    assert np.abs(level_db).max() < 1.0, np.abs(level_db).max()

    # It is where the receivers say, sum(p_i y_i) / sum(p_i) of the values sent, some
    # time ago: the window averages 11 ms, the engine ramps over a 5.3 ms block, the
    # smoothing lags 5 ms (about three frames in all), and the threads of sender, bridge
    # and engine wait for a core now and then: the phantom is where the values of one of
    # the last nine frames (100 ms) put it, and of as many more frames as a thread of this
    # process was at most woken late meanwhile, nearly always within 0.5 mm, and never
    # far off.
    late_frames = int(np.ceil(lag.worst_s / FRAME_S))
    print(f"woken up to {lag.worst_s * 1e3:.1f} ms late, {late_frames} frames more; on time for")
    print(f"{lag.on_time_fraction:.2f} of the time; {sliding.sum()} windows")

    def lagged_error(reference: Callable[[int], float]) -> np.ndarray:
        return np.array(
            [
                min(abs(yi - reference(j)) for j in range(i - 8 - late_frames, i + 1))
                for yi, i in zip(y, k[sliding], strict=True)
            ]
        )

    error_cm = lagged_error(weighted_y)
    assert np.percentile(error_cm, 95) < 0.05, np.percentile(error_cm, 95)
    assert error_cm.max() < 0.3, error_cm.max()
    # So it follows the hand as closely as spheres of 6 cm on a 4.8 cm grid allow: their
    # weighted mean is up to 0.55 cm off the hand between two rows.
    hand_error_cm = lagged_error(lambda j: hand(j * FRAME_S)[1])
    assert hand_error_cm.max() < 0.55 + 0.3, hand_error_cm.max()
    assert np.abs(centroid[sliding, 0] - X_CM).max() < 0.05
    # And it is gone once the hand has lifted.
    after = frame_of > sent[-1] + 0.2 * DEVICE.sample_rate_hz
    assert energy[after].max() < 1e-9


def test_silence_releases_the_contact(engine) -> None:
    """A stream that stops with the hand still on the arm: the watchdog lets go."""
    eng, _ = engine
    receivers = _map(watchdog_s=0.4)
    with OscBridge(osc_admission(eng), receivers, port=0) as bridge:
        client = SimpleUDPClient(*bridge.address)
        send_stream(client, receivers, lambda t: (X_CM, 7.2 - t, 1.0), 0.3)
        assert bridge.contacts == ["receivers-0"]
        owners = [c["owner"] for c in eng.status().to_dict()["active_contacts"]]
        assert len(owners) == 1 and owners[0].startswith("osc:127.0.0.1/"), owners
        deadline = time.monotonic() + 2.0
        while bridge.contacts and time.monotonic() < deadline:
            time.sleep(0.02)
        assert bridge.contacts == []
        assert bridge.watchdog_releases == 1
        while eng.status().to_dict()["active_contacts"] and time.monotonic() < deadline + 5.0:
            time.sleep(0.01)
        assert eng.status().to_dict()["active_contacts"] == []


def test_two_separate_touches_are_two_contacts(engine) -> None:
    """Receivers at the wrist and at the elbow, nothing between: two phantoms."""
    eng, _ = engine
    receivers = _map()
    values = {0: 0.8, 4: 0.8, 3: 0.5, 7: 0.5}  # rows at y=0 and y=14.4, both columns
    with OscBridge(osc_admission(eng), receivers, port=0) as bridge:
        client = SimpleUDPClient(*bridge.address)
        for i, value in values.items():
            client.send_message(receivers.receiver[i].address, value)
        deadline = time.monotonic() + 2.0
        while len(bridge.contacts) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert bridge.contacts == ["receivers-0", "receivers-1"]
        contacts = eng.status().to_dict()["active_contacts"]
        ys = sorted(round(c["y_cm"], 6) for c in contacts)
        assert ys == [0.0, 14.4]
