"""What the Python client's tests share: a stroke pattern and the states of a job."""

from __future__ import annotations

from phantomtouch_client import TouchPattern

STROKE = TouchPattern.model_validate(
    {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 20.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
    }
)
JOB_STATES = {"scheduled", "playing", "finished", "stopped"}
