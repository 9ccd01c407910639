"""Every input as a client speaks it, for the attack table (:mod:`tests.attacks.test_table`).

An input is a class with a *stand* (the real processes it needs: a ``phantomtouch serve``
with a capture output, and for fleet a NATS server, an armband node and a gateway) and
*sources* (one client: a WebSocket connection, an HTTP client, an OSC sender's port, a
bHaptics game). Every source can do the same things, each in its own protocol:

- :meth:`hold`: start something felt that lasts a minute unless the input's rule ends it
  sooner (a contact, a frame and a key, a touch);
- :meth:`renew`: one message of the source (its protocol's keep-alive);
- :meth:`huge`: one message carrying the most work the input lets one message carry;
- :meth:`plan_big`: send a touch that takes long to plan, without waiting for its answer;
- :meth:`long_score`: start a 30 s touch (a score, a stored pattern);
- :meth:`bad_values`: send NaN, infinite and huge values in every field that takes a number;
- :meth:`close`: go away.

This module imports nothing of phantomtouch: it speaks each protocol from its docs
(docs/api.md, docs/osc.md, docs/bhaptics.md, docs/fleet.md).
"""

from __future__ import annotations

import contextlib
import json
import math
import socket
import threading
import time
from typing import Any, ClassVar

import httpx
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from tests.bhaptics.player_client import crowd_project, frame_submits
from tests.bhaptics.test_standin_live import dot_project

LONG_S = 60.0
"""How long a held touch would last if nothing ended it."""
SCORE_S = 30.0
"""The length of a long score."""
REST_TOUCH_S = 2.0
"""A REST client asks for a touch's length; this is its "deadline"."""
BIG_POINTS = 40_000
"""Points of the pattern that takes long to plan (as many as fit a 1 MiB body)."""


def polyline(points: int, duration_s: float, intensity: float = 0.5) -> dict[str, Any]:
    """A touch along the band through ``points`` points (zig-zag around 1.9 cm)."""
    path = [
        [round(1.9 + 0.001 * (k % 2), 3), round(2.4 + 9.6 * k / max(1, points - 1), 3)]
        for k in range(points)
    ]
    return {
        "path": {"kind": "polyline", "points_cm": path},
        "duration_s": duration_s,
        "intensity": intensity,
    }


BAD_NUMBERS = (math.nan, math.inf, -math.inf, 1e308, -1e308)
OSC_BAD_NUMBERS = (math.nan, math.inf, -math.inf, 3.4e38, -3.4e38)
"""OSC floats are 32-bit: the largest finite ones instead of 1e308."""


class WsSource:
    """A ``/ws`` connection (a gateway's, with ``armband``); its messages are read by a
    thread of its own (kept in :attr:`seen`)."""

    def __init__(self, url: str, *, local: str = "127.0.0.1", armband: str | None = None):
        self.ws: ClientConnection = connect(
            url, source_address=(local, 0), max_size=None, compression=None
        )
        self.armband = armband
        self.seen: list[dict[str, Any]] = []
        self._ids = iter(range(1, 1 << 30))
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        try:
            for text in self.ws:
                self.seen.append(json.loads(text))
        except Exception:  # the connection ended: nothing more to read
            return

    def send(self, message: dict[str, Any]) -> None:
        """Send ``message``; nothing once the server closed the connection (a source whose
        slot went to a newcomer says nothing more)."""
        routed = {**message, "armband": self.armband} if self.armband else message
        with contextlib.suppress(ConnectionClosed):
            self.ws.send(json.dumps(routed))

    def hold(self, x_cm: float = 1.9, y_cm: float = 7.2, intensity: float = 1.0) -> None:
        self.send(
            {"type": "down", "contact": "held", "x_cm": x_cm, "y_cm": y_cm, "intensity": intensity}
        )

    def move(self, x_cm: float, y_cm: float) -> None:
        self.send({"type": "move", "contact": "held", "x_cm": x_cm, "y_cm": y_cm})

    def renew(self) -> None:
        self.send({"type": "ping", "id": next(self._ids)})

    def huge(self) -> None:
        self.send({"type": "play", "id": next(self._ids), **polyline(3_000, 3600.0, 0.05)})

    def plan_big(self) -> None:
        self.send({"type": "play", "id": next(self._ids), **polyline(3_000, 8.0)})

    def long_score(self) -> None:
        self.send({"type": "play", "id": next(self._ids), **polyline(20, SCORE_S)})

    def bad_values(self) -> None:
        for bad in BAD_NUMBERS:
            self.send({"type": "down", "contact": "bad", "x_cm": bad, "y_cm": 7.2})
            self.send(
                {"type": "down", "contact": "bad", "x_cm": 1.9, "y_cm": 7.2, "intensity": bad}
            )
            self.send({"type": "play", "id": next(self._ids), **polyline(2, bad)})
            self.send({"type": "play", "id": next(self._ids), **polyline(2, 3.0, bad)})

    def close(self) -> None:
        self.ws.close()


class RestSource:
    """An HTTP client from ``local`` (keep-alive)."""

    def __init__(self, url: str, *, local: str = "127.0.0.1"):
        self.url = url
        self.http = httpx.Client(
            base_url=url, timeout=60.0, transport=httpx.HTTPTransport(local_address=local)
        )

    def _post(self, body: dict[str, Any]) -> None:
        self.http.post("/touch", json=body)

    def hold(self, x_cm: float = 1.9, y_cm: float = 7.2, intensity: float = 1.0) -> None:
        self._post(
            {
                "path": {"kind": "polyline", "points_cm": [[x_cm, y_cm]]},
                "duration_s": REST_TOUCH_S,
                "intensity": intensity,
            }
        )

    def renew(self) -> None:
        self.http.get("/health")

    def huge(self) -> None:
        self._post(polyline(BIG_POINTS, 3600.0, 0.05))

    def plan_big(self) -> None:
        body = json.dumps(polyline(BIG_POINTS, 8.0))
        threading.Thread(
            target=lambda: httpx.post(
                f"{self.url}/touch",
                content=body,
                headers={"Content-Type": "application/json"},
                timeout=60.0,
            ),
            daemon=True,
        ).start()

    def long_score(self) -> None:
        self._post(polyline(20, SCORE_S))

    def bad_values(self) -> None:
        for bad in BAD_NUMBERS:
            for body in (polyline(2, bad), polyline(2, 3.0, bad)):
                self.http.post(
                    "/touch",
                    content=json.dumps(body),
                    headers={"Content-Type": "application/json"},
                )
            points = {"path": {"kind": "polyline", "points_cm": [[bad, 7.2]]}, "duration_s": 1.0}
            self.http.post(
                "/touch", content=json.dumps(points), headers={"Content-Type": "application/json"}
            )

    def close(self) -> None:
        self.http.close()


def osc_message(address: str, *args: float | str) -> bytes:
    builder = OscMessageBuilder(address=address)
    for arg in args:
        builder.add_arg(arg)
    return bytes(builder.build().dgram)


class OscSource:
    """An OSC sender: one UDP port of ``local``."""

    STORED = ("attack-big", "attack-long")
    """Patterns the stand stores for it (OSC plays stored patterns by name)."""

    def __init__(self, target: str, *, local: str = "127.0.0.1"):
        host, port = target.rsplit(":", 1)
        self.target = (host, int(port))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((local, 0))
        self._held: tuple[float, float, float] | None = None

    def send(self, datagram: bytes) -> None:
        self.sock.sendto(datagram, self.target)

    def hold(self, x_cm: float = 1.9, y_cm: float = 7.2, intensity: float = 1.0) -> None:
        self._held = (x_cm, y_cm, intensity)
        self.send(osc_message("/phantomtouch/contact/held", x_cm, y_cm, intensity))

    def move(self, x_cm: float, y_cm: float) -> None:
        self.hold(x_cm, y_cm, 1.0)

    def renew(self) -> None:
        if self._held is not None:
            self.hold(*self._held)
        else:
            self.send(osc_message("/phantomtouch/contact/held", 1.9, 7.2, 0.0))

    def huge(self) -> None:
        bundle = OscBundleBuilder(IMMEDIATELY)
        for k in range(1_000):  # a bundle of 1,000 messages: as many as fit a datagram
            bundle.add_content(_contact_message(k))
        self.send(bytes(bundle.build().dgram))

    def plan_big(self) -> None:
        self.send(osc_message("/phantomtouch/touch", self.STORED[0]))

    def long_score(self) -> None:
        self.send(osc_message("/phantomtouch/touch", self.STORED[1]))

    def bad_values(self) -> None:
        for bad in OSC_BAD_NUMBERS:
            self.send(osc_message("/phantomtouch/contact/bad", bad, 7.2, 0.5))
            self.send(osc_message("/phantomtouch/contact/bad", 1.9, 7.2, bad))
        self.send(osc_message("/phantomtouch/contact/bad", 1.9, 7.2, 0.0))

    def close(self) -> None:
        self.sock.close()


def _contact_message(k: int) -> Any:
    builder = OscMessageBuilder(address=f"/phantomtouch/contact/c{k}")
    for arg in (1.9, 2.4 + (k % 20) * 0.4, 0.3):
        builder.add_arg(arg)
    return builder.build()


def bhaptics_frame(key: str, index: int, duration_ms: float, intensity: Any = 80) -> dict[str, Any]:
    return {
        "Type": "frame",
        "Key": key,
        "Frame": {
            "Position": "ForearmL",
            "DotPoints": [{"Index": index, "Intensity": intensity}],
            "PathPoints": [],
            "DurationMillis": duration_ms,
        },
    }


class BhapticsSource:
    """A game on the stand-in's ``/v2/feedbacks``; statuses read by a thread of its own."""

    def __init__(self, url: str, *, local: str = "127.0.0.1"):
        self.ws = connect(url, source_address=(local, 0), max_size=None, compression=None)
        self.statuses: list[Any] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self._wait(0, 60.0)  # the status every connection gets first

    def _wait(self, before: int, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while len(self.statuses) <= before and time.monotonic() < end:
            time.sleep(0.005)

    def _read(self) -> None:
        try:
            for text in self.ws:
                self.statuses.append(json.loads(text))
        except Exception:  # the connection ended: nothing more to read
            return

    def send(self, message: dict[str, Any] | str) -> None:
        """Send ``message``; nothing once the server closed the connection."""
        with contextlib.suppress(ConnectionClosed):
            self.ws.send(message if isinstance(message, str) else json.dumps(message))

    def ask(self, message: dict[str, Any] | str, timeout_s: float = 60.0) -> None:
        """Send and wait for the status that answers it."""
        before = len(self.statuses)
        self.send(message)
        self._wait(before, timeout_s)

    def hold(self, x_cm: float = 1.9, y_cm: float = 7.2, intensity: float = 1.0) -> None:
        """A key and a frame, a minute each. A game names motors, not places: the far half
        of the band (``y_cm`` >= 7) gets the left arm's motor 2 and the right arm's 0, the
        near half motor 3 only."""
        del x_cm
        level = round(100 * intensity)
        length_ms = round(LONG_S * 1000)
        if y_cm < 7.0:
            self.ask({"Submit": [bhaptics_frame("held-frame", 3, length_ms, level)]})
            return
        self.ask({"Register": [{"Key": "held", "Project": dot_project("ForearmR", 0, length_ms)}]})
        self.ask(
            {
                "Submit": [
                    {"Type": "key", "Key": "held"},
                    bhaptics_frame("held-frame", 2, length_ms, level),
                ]
            }
        )

    def renew(self) -> None:
        """The SDKs' keep-alive: an empty frame on a foot."""
        empty = {"Position": "FootL", "DotPoints": [], "PathPoints": [], "DurationMillis": 100}
        self.send({"Submit": [{"Type": "frame", "Key": "ping", "Frame": empty}]})

    def huge(self) -> None:
        self.ask(frame_submits(30_000))

    def plan_big(self) -> None:
        self.ask({"Register": [{"Key": "crowd", "Project": crowd_project(200, 8000, 40)}]})
        self.send({"Submit": [{"Type": "key", "Key": "crowd"}]})

    def long_score(self) -> None:
        length_ms = round(SCORE_S * 1000)
        self.ask({"Register": [{"Key": "score", "Project": dot_project("ForearmR", 1, length_ms)}]})
        self.ask({"Submit": [{"Type": "key", "Key": "score"}]})

    def bad_values(self) -> None:
        for bad in BAD_NUMBERS:
            self.send({"Submit": [bhaptics_frame("bad", 3, bad, 80)]})
            self.send({"Submit": [bhaptics_frame("bad", 3, 300, bad)]})
            self.send(
                {
                    "Submit": [
                        {
                            "Type": "key",
                            "Key": "held",
                            "Parameters": {"scaleOption": {"intensity": bad, "duration": bad}},
                        }
                    ]
                }
            )
        self.send({"Submit": [{"Type": "turnOffAll"}]})

    def close(self) -> None:
        self.ws.close()


class Input:
    """An input of the table: its kind, how long a silent source's touch lasts, how many
    connection slots it has, and how to open a source."""

    kind: ClassVar[str]
    silence_ends_s: ClassVar[float]
    """What a source holds ends this long after its last message (REST: the touch's own
    length)."""
    close_ends_s: ClassVar[float]
    """What a source holds ends this long after it goes (0: at once, with the release)."""
    slots: ClassVar[int]
    """Sources an idle crowd opens: the input's connection slots."""
    transit_s: ClassVar[float] = 0.1
    """How long after it is sent a message may count at the armband's engine: a deadline
    or a release counts from its arrival there, once the service's event loop and the
    engine's deadline thread have had their turn on a busy machine."""

    def __init__(self, target: str) -> None:
        self.target = target

    def source(self, local: str = "127.0.0.1") -> Any:
        raise NotImplementedError

    @classmethod
    def hung_source(cls, target: str) -> Any:
        """A source for :mod:`tests.attacks.hung_client`."""
        return cls(target).source()


class WsInput(Input):
    kind = "ws"
    silence_ends_s = 2.0  # watchdog_s
    close_ends_s = 0.0
    slots = 64  # max_ws_connections

    def source(self, local: str = "127.0.0.1") -> WsSource:
        return WsSource(self.target, local=local)


class RestInput(Input):
    kind = "rest"
    silence_ends_s = REST_TOUCH_S
    close_ends_s = REST_TOUCH_S
    slots = 64

    def source(self, local: str = "127.0.0.1") -> RestSource:
        return RestSource(self.target, local=local)


class OscInput(Input):
    kind = "osc"
    silence_ends_s = 1.0  # the default map's watchdog_s
    close_ends_s = 1.0  # a sender that goes is a sender that is silent
    slots = 256

    def source(self, local: str = "127.0.0.1") -> OscSource:
        return OscSource(self.target, local=local)


class BhapticsInput(Input):
    kind = "bhaptics"
    silence_ends_s = 5.0  # the stand-in's deadline
    close_ends_s = 0.0
    slots = 8

    def source(self, local: str = "127.0.0.1") -> BhapticsSource:
        return BhapticsSource(self.target, local=local)


class FleetInput(Input):
    """The target is ``GATEWAY_WS_URL ARMBAND``."""

    kind = "fleet"
    silence_ends_s = 2.0  # the watchdog_s the gateway announces in its welcome
    close_ends_s = 0.0
    slots = 64
    transit_s = 0.25  # through the gateway and NATS to the armband's node, on a loaded machine

    def source(self, local: str = "127.0.0.1") -> WsSource:
        url, armband = self.target.split(" ")
        return WsSource(url, local=local, armband=armband)


INPUT_CLASSES: dict[str, type[Input]] = {
    cls.kind: cls for cls in (WsInput, RestInput, OscInput, BhapticsInput, FleetInput)
}
