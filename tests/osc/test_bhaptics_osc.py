"""A bHapticsOSC avatar over real UDP (python-osc): each parameter a phantom at its motor.

bHapticsOSC names the arm parameters ``bHapticsOSC_Arm_Left_1`` .. ``_6`` and
``bHapticsOSC_Arm_Right_1`` .. ``_6``; ``_k`` is Tactosy motor index ``k - 1``, whose place
on the band is the mapping's (docs/bhaptics.md): index 2 (x 1, y 0) at the far end on the
first column, index 4 (x 0.5, y 1) in the middle of the second column.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.engine import Engine
from phantomtouch.osc.bridge import OscBridge
from phantomtouch.osc.mapping import BHAPTICS_PREFIX, bhaptics_map, load_map
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile
from tests.osc.support import energy_track, osc_admission

DEVICE = DeviceProfile.default()


@pytest.fixture
def engine() -> Iterator[tuple[Engine, CaptureSink]]:
    sink = CaptureSink(DEVICE, realtime=True)
    with Engine(DEVICE, sink) as engine:
        yield engine, sink


def test_the_map_has_twelve_parameters_on_the_motors_places() -> None:
    receivers = {r.address: (r.x_cm, r.y_cm) for r in load_map(Path("bhaptics"), DEVICE).receiver}
    assert len(receivers) == 12
    assert receivers[f"{BHAPTICS_PREFIX}Left_1"] == (0.0, 0.0)
    assert receivers[f"{BHAPTICS_PREFIX}Left_3"] == (0.0, 14.4)
    assert receivers[f"{BHAPTICS_PREFIX}Right_5"] == (3.8, 7.2)
    assert receivers[f"{BHAPTICS_PREFIX}Right_4"] == (3.8, 0.0)
    one_arm = bhaptics_map(DEVICE, ArmMap(arms=["ForearmR"]))
    assert {r.address.rsplit("_", 2)[1] for r in one_arm.receiver} == {"Right"}


@pytest.mark.parametrize(
    ("parameter", "place"),
    [("Left_3", (0.0, 14.4)), ("Right_5", (3.8, 7.2)), ("Left_1", (0.0, 0.0))],
)
def test_a_parameter_is_a_phantom_at_its_motors_place(
    engine, parameter: str, place: tuple[float, float]
) -> None:
    eng, sink = engine
    receivers = bhaptics_map(DEVICE)
    with OscBridge(osc_admission(eng), receivers, port=0) as bridge:
        client = SimpleUDPClient(*bridge.address)
        client.send_message(f"{BHAPTICS_PREFIX}{parameter}", 1.0)
        deadline = time.monotonic() + 3.0
        while not bridge.contacts and time.monotonic() < deadline:
            time.sleep(0.01)
        assert bridge.contacts, "no contact"
        start = eng.now_frames
        while eng.now_frames < start + 0.3 * DEVICE.sample_rate_hz:
            assert time.monotonic() < deadline + 5.0, "the engine's clock stalled"
            time.sleep(0.02)
        client.send_message(f"{BHAPTICS_PREFIX}{parameter}", 0.0)
        while bridge.contacts and time.monotonic() < deadline + 5.0:
            time.sleep(0.01)
        assert bridge.contacts == []
    window = DEVICE.sample_rate_hz // 100
    energy, centroid = energy_track(sink.recording(), DEVICE, window)
    loud = energy > 0.5 * energy.max()
    assert loud.sum() >= 20  # 0.2 s of it at least
    assert np.hypot(*(centroid[loud] - place).T).max() < 0.5, centroid[loud].mean(axis=0)


def test_two_neighbouring_parameters_are_one_phantom_between_their_motors(engine) -> None:
    """A hand between motors 1 and 2 of the left sleeve (0 and 7.2 cm along the band),
    both receivers full, re-sent at 90 Hz for 0.3 s: one contact half way, at 3.6 cm."""
    eng, _ = engine
    with OscBridge(osc_admission(eng), bhaptics_map(DEVICE), port=0) as bridge:
        client = SimpleUDPClient(*bridge.address)
        for _ in range(27):
            client.send_message(f"{BHAPTICS_PREFIX}Left_1", 1.0)
            client.send_message(f"{BHAPTICS_PREFIX}Left_2", 1.0)
            time.sleep(1 / 90)
        assert bridge.contacts == ["receivers-0"]
        contacts = eng.status().to_dict()["active_contacts"]
        assert len(contacts) == 1
        assert contacts[0]["y_cm"] == pytest.approx(3.6, abs=0.05)
        assert contacts[0]["x_cm"] == pytest.approx(0.0, abs=0.05)
