"""Contacts that arrive over NATS reach the engine's output, and only well-formed ones."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import numpy as np
import pytest
from pydantic import ValidationError

from phantomtouch.engine import CaptureSink, Engine
from phantomtouch.errors import ProtocolError
from phantomtouch.fleet.remote_contacts import RemoteContacts
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.errors import QuotaError, TooLargeError

DEVICE = DeviceProfile.default()
WATCHDOG_S = 0.5


@pytest.fixture
def captured() -> Iterator[tuple[RemoteContacts, CaptureSink]]:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        yield RemoteContacts(engine, watchdog_s=WATCHDOG_S, max_contacts=2, max_bytes=1024), sink


def _message(**fields: object) -> bytes:
    return json.dumps({"owner": "gw-1", **fields}).encode()


def test_a_remote_down_drives_the_actuator_under_it_only(
    captured: tuple[RemoteContacts, CaptureSink],
) -> None:
    contacts, sink = captured
    assert (
        contacts.handle(_message(type="down", contact="f", x_cm=0.0, y_cm=4.8), now_s=0.0) == "down"
    )
    recording = sink.pull(8)
    assert np.any(recording[:, 1])  # actuator 2 sits at (0, 4.8) cm on channel 2
    assert not np.any(np.delete(recording, 1, axis=1))


def test_a_silent_owner_is_released_by_the_watchdog(
    captured: tuple[RemoteContacts, CaptureSink],
) -> None:
    contacts, sink = captured
    start_s = time.monotonic()  # the engine's deadlines run on this clock
    contacts.handle(_message(type="down", contact="f", x_cm=1.9, y_cm=7.2), now_s=start_s)
    contacts.handle(_message(type="ping"), now_s=start_s + 0.4)
    assert contacts.release_silent(now_s=start_s + 0.4 + WATCHDOG_S / 2) == []
    assert contacts.release_silent(now_s=start_s + 0.4 + WATCHDOG_S * 1.01) == ["gw-1"]
    sink.pull(40)  # the release ramp
    assert not np.any(sink.pull(2))


@pytest.mark.parametrize(
    ("data", "error"),
    [
        (b"not json", ProtocolError),
        (b"[1, 2]", ProtocolError),
        (
            json.dumps({"type": "down", "contact": "f", "x_cm": 1, "y_cm": 1}).encode(),
            ProtocolError,
        ),
        (_message(type="move", contact="f", x_cm=1.0, y_cm=1.0), ProtocolError),
        (_message(type="down", contact="f", x_cm="far", y_cm=1.0), ValidationError),
        (_message(type="down", contact="f", x_cm=1.0, y_cm=1.0, speed=3), ValidationError),
        (_message(type="teleport"), ProtocolError),
        (_message(type="down", contact="f", x_cm=1.0, y_cm=1.0, pad="x" * 2000), TooLargeError),
    ],
)
def test_a_bad_message_is_refused_and_plays_nothing(
    captured: tuple[RemoteContacts, CaptureSink], data: bytes, error: type[Exception]
) -> None:
    contacts, sink = captured
    with pytest.raises(error):
        contacts.handle(data, now_s=0.0)
    assert not np.any(sink.pull(4))


def test_the_contact_quota_holds_per_owner(captured: tuple[RemoteContacts, CaptureSink]) -> None:
    contacts, _ = captured
    for contact in ("a", "b"):
        contacts.handle(_message(type="down", contact=contact, x_cm=1.0, y_cm=1.0), now_s=0.0)
    with pytest.raises(QuotaError, match="max_contacts_per_connection=2"):
        contacts.handle(_message(type="down", contact="c", x_cm=1.0, y_cm=1.0), now_s=0.0)
    other = json.dumps({"owner": "gw-2", "type": "down", "contact": "c", "x_cm": 1, "y_cm": 1})
    assert contacts.handle(other.encode(), now_s=0.0) == "down"
    assert contacts.count() == 3
