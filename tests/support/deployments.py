"""SDK2 deployments for tests, built in the Developer Portal's shape.

No deployment under a licence that allows copying is known, so tests build them
(docs/bhaptics.md, "SDK2"): ``tactFilePatterns`` from the corpus's real ``.tact`` files
(``tests/clips/samples/tact/bhaptics-popone-support``, MIT) and ``audioFilePatterns`` from
frames written here.
"""

from __future__ import annotations

import base64
import copy
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

CORPUS = Path(__file__).parents[1] / "clips" / "samples" / "tact" / "bhaptics-popone-support"


def tact(name: str, folder: str = "Arm") -> dict[str, Any]:
    """The ``project`` object of a corpus file (what a deployment's ``tactFile`` holds)."""
    path = CORPUS / folder / f"{name}.tact"
    project: dict[str, Any] = json.loads(path.read_text(encoding="utf-8-sig"))["project"]
    return project


def effects_end_ms(project: dict[str, Any]) -> float:
    """The latest ``startTime + offsetTime`` of an enabled track's effect, from the JSON
    alone (an effect lasts ``offsetTime`` ms from its ``startTime``)."""
    ends = [
        float(e["startTime"]) + float(e["offsetTime"])
        for track in project["tracks"]
        if track.get("enable", True) is not False
        for e in track["effects"]
    ]
    return max(ends, default=0.0)


def frame(*levels: int) -> str:
    """One audio frame: ``levels`` (0-255) for the first motors, the rest of the 20 bytes 0."""
    return base64.b64encode(bytes(levels) + bytes(20 - len(levels))).decode()


def mapping(
    key: str,
    *,
    tact_files: Iterable[tuple[str, Any]] = (),
    clips: Iterable[dict[str, Any]] = (),
    **extra: Any,
) -> dict[str, Any]:
    """One event: ``tact_files`` as ``(position label, tactFile)``, ``clips`` the
    ``audioFilePatterns`` clips (copied); ``extra`` replaces any field."""
    return {
        "enable": True,
        "intensity": 100,
        "key": key,
        "category": "Gameplay",
        "description": "",
        "updateTime": 1694710443550,
        "tactFilePatterns": [{"position": label, "tactFile": t} for label, t in tact_files],
        "audioFilePatterns": [
            {"patternId": "", "snapshotId": "", "position": "Vest", "clip": copy.deepcopy(c)}
            for c in clips
        ],
        "eventTime": 100,
        **extra,
    }


def portal(*mappings: dict[str, Any], workspace: str = "ws-123") -> dict[str, Any]:
    """The Developer Portal's answer around ``mappings``."""
    return {
        "status": True,
        "code": 200,
        "errorMessage": None,
        "timestamp": 1694710443550,
        "message": {
            "id": "dep-1",
            "createTime": 1694710443550,
            "name": "A Game",
            "creator": "someone",
            "workspaceId": workspace,
            "version": 7,
            "disableValidation": False,
            "hapticMappings": list(mappings),
            "categoryOptions": ["Gameplay"],
            "description": "",
        },
    }


RECOIL = tact("RecoilLevel2_R")
"""200 ms on ``ForearmR`` alone."""
CLIMB = tact("Climbing_L")
"""274 ms on ``ForearmL`` alone."""
ARM_CLIP: dict[str, Any] = {
    "id": "",
    "name": "hit",
    "version": -1,
    "duration": 4,  # seen in real deployments: not a length
    "patterns": {
        "ForearmL": [frame(0, 0, 50), frame(0, 0, 50), frame(0, 0, 50)],
        "ForearmR": [frame()] * 5,
        "VestFront": [frame(100, 100)] * 2,
    },
}
"""Motor 2 of ``ForearmL`` at 50 for 60 ms; the clip lasts 100 ms (``ForearmR``'s 5 frames)."""
VEST_CLIP: dict[str, Any] = {"patterns": {"VestFront": [frame(100)] * 3}}
"""60 ms on the vest only."""
BOTH = portal(
    mapping("recoil", tact_files=[("LeftArm", RECOIL)]),
    mapping("climb", tact_files=[("Vest", CLIMB)], clips=[ARM_CLIP]),
    mapping("hit", clips=[ARM_CLIP]),
)
"""A deployment holding both pattern kinds: ``recoil`` (a ``.tact`` labelled ``LeftArm``
whose content is on ``ForearmR``), ``climb`` (both kinds) and ``hit`` (audio only)."""
