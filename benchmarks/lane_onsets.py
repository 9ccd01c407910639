"""Onsets on the service's JACK ports, for :mod:`bench_lane`: a JACK client of its own that
finds when a channel passes a level, and waits for the channels to fall quiet."""

from __future__ import annotations

import asyncio
import math
import threading
import time
import uuid

import numpy as np

from tests.support.jack import JackServer

QUIET_TIMEOUT_S = 5.0
"""Longest wait for the contact to leave the far actuator before the next measured move."""


class Onsets:
    """A JACK client finding when one channel passes a level (after :meth:`arm`)."""

    def __init__(self, server: JackServer) -> None:
        import jack

        self.client = jack.Client(
            f"lane-{uuid.uuid4().hex[:6]}", servername=server.name, no_start_server=True
        )
        self.inputs = [self.client.inports.register(f"in_{k + 1}") for k in range(8)]
        self.rate_hz = self.client.samplerate
        self.seen = threading.Event()
        self.onset_s = 0.0
        self.peak = np.zeros(8)
        self.recent = np.zeros(8)
        """Each channel's largest magnitude in the last period."""
        self._channel: int | None = None
        self._level = math.inf
        self._armed = False
        self.client.set_process_callback(self._process)
        self.client.activate()

    def connect(self, client_name: str) -> None:
        """Connect the outputs of the JACK client ``client_name`` (a service) to the inputs."""
        for port in self.inputs:
            for other in self.client.get_all_connections(port):
                self.client.disconnect(other, port)
        ports = self.client.get_ports(f"^{client_name}:", is_output=True, is_audio=True)
        ports = sorted(ports, key=lambda p: int(p.name.rsplit("_", 1)[-1]))
        if len(ports) != len(self.inputs):
            names = [p.name for p in self.client.get_ports(is_audio=True)]
            raise RuntimeError(f"the service's 8 output ports are not on JACK: {names}")
        for source, sink in zip(ports, self.inputs, strict=True):
            self.client.connect(source, sink)

    def arm(self, channel: int | None, level: float) -> None:
        """Find the next sample past ``level`` on ``channel`` (None: on any)."""
        self.seen.clear()
        self._channel, self._level = channel, level
        self._armed = True

    def _process(self, frames: int) -> None:
        now_s = time.monotonic()
        for k, port in enumerate(self.inputs):
            self.recent[k] = float(np.abs(port.get_array()).max())
        np.maximum(self.peak, self.recent, out=self.peak)
        if not self._armed:
            return
        watched = self.inputs if self._channel is None else [self.inputs[self._channel]]
        loud = np.zeros(frames, dtype=bool)
        for port in watched:
            loud |= np.abs(port.get_array()) > self._level
        found = np.flatnonzero(loud)
        if found.size:
            self.onset_s = now_s + found[0] / self.rate_hz
            self._armed = False
            self.seen.set()

    async def quiet(self, channel: int | None, level: float) -> bool:
        """Wait until ``channel`` (None: every channel) stays below ``level`` for a period
        (what was sent before has landed); False if it does not within a few seconds."""
        deadline = time.monotonic() + QUIET_TIMEOUT_S
        watched = slice(None) if channel is None else slice(channel, channel + 1)
        while time.monotonic() < deadline:
            if self.recent[watched].max() < level:
                return True
            await asyncio.sleep(0.005)
        return False

    def close(self) -> None:
        self.client.deactivate()
        self.client.close()
