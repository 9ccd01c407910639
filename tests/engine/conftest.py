"""Fixtures of the engine tests: a private JACK server (the seeded ``rng`` is shared)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.support.jack import JackServer, start_jack_or_skip


@pytest.fixture(scope="module")
def jack_server() -> Iterator[JackServer]:
    """A JACK dummy server at 48 kHz, 256-frame periods, 8 outputs (one per module)."""
    server = start_jack_or_skip(sample_rate_hz=48000, period_frames=256, channels=8)
    yield server
    server.stop()
