"""Shared pieces of the service tests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from phantomtouch.service.settings import Settings

STROKE: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
    "speed_cm_s": 5.0,
}
"""A 3.12 s stroke down the middle of the armband."""

LONG: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 12.0]]},
    "duration_s": 30.0,
}
"""A 30 s touch that stays in place: still playing when a test looks at it."""


def make_settings(tmp_path: Path, **changes: Any) -> Settings:
    """Settings for an in-process test: null output, the test's own database.

    The engine runs in a thread of the test process (it starts in milliseconds); the
    live-server tests run the default, the engine in a process of its own. The service
    answers to ``testserver``, the host name ``TestClient`` sends.
    """
    options = {"engine_process": False, "allowed_hosts": ["testserver"], **changes}
    return Settings(db_path=tmp_path / "patterns.db", output_device="null", **options)
