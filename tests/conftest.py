"""Shared fixtures: a seeded random generator, a repeatable hypothesis profile and a
private JACK server (for the engine's and the output layer's tests)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from tests.support.jack import JackServer, start_jack_or_skip

# Property tests run the same examples on every machine (derandomize), never time out on
# a loaded CI core (deadline=None) and stay few enough to keep the suite short.
settings.register_profile(
    "phantomtouch",
    derandomize=True,
    deadline=None,
    database=None,
    max_examples=30,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile("phantomtouch")


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: tests draw from it, never from the global random state."""
    return np.random.default_rng(20230915)


@pytest.fixture(scope="module")
def jack_server() -> Iterator[JackServer]:
    """A JACK dummy server at 48 kHz, 256-frame periods, 8 outputs (one per module)."""
    server = start_jack_or_skip(sample_rate_hz=48000, period_frames=256, channels=8)
    yield server
    server.stop()
