"""Shared fixtures: a seeded random generator and a repeatable hypothesis profile."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

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
