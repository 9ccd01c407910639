"""Test deployments in the Developer Portal's shape (docs/bhaptics.md, "SDK2"), built here
from ``.tact`` projects and audio frames, and the two ``SdkRequestAuthInit`` spellings seen
on the wire: bHaptics' own library 0.2.2 (PascalCase envelope and ``authentication`` keys,
``authentication`` and ``haptic`` JSON strings) and a real game's (lower case, camelCase
``authentication``)."""

from __future__ import annotations

import base64
import json
from collections.abc import Sequence
from typing import Any

from tests.bhaptics.test_standin_live import dot_project

FRAME_MS = 20


def audio_frames(motor: int, level: int, frames: int) -> list[str]:
    """``frames`` base64 frames of 20 motor bytes with ``motor`` at ``level``."""
    frame = bytearray(20)
    frame[motor] = level
    return [base64.b64encode(bytes(frame)).decode("ascii")] * frames


def mapping(
    key: str,
    *,
    tact: Sequence[dict[str, Any]] = (),
    audio: dict[str, list[str]] | None = None,
    event_time: int = 0,
) -> dict[str, Any]:
    """One ``hapticMappings`` entry: its ``.tact`` projects (labelled ``LeftArm``, a label
    only) and its audio frames per device."""
    return {
        "id": f"id-{key}",
        "enable": True,
        "intensity": 100,
        "key": key,
        "category": "test",
        "description": "",
        "updateTime": 1694710443550,
        "eventTime": event_time,
        "tactFilePatterns": [
            {"position": "LeftArm", "tactFile": {"name": key, **project}} for project in tact
        ],
        "audioFilePatterns": []
        if audio is None
        else [{"position": "Vest", "clip": {"duration": 4, "patterns": audio}}],
    }


def deployment(workspace: str, mappings: list[dict[str, Any]]) -> dict[str, Any]:
    """The Developer Portal's answer holding ``mappings``."""
    return {
        "status": True,
        "code": 200,
        "errorMessage": None,
        "timestamp": 1694710443550,
        "message": {
            "id": "deploy-1",
            "createTime": 1694710443550,
            "name": "phantomtouch test game",
            "creator": "test",
            "workspaceId": workspace,
            "version": 3,
            "disableValidation": False,
            "hapticMappings": mappings,
            "categoryOptions": [],
            "description": "",
        },
    }


def game_events(workspace: str) -> dict[str, Any]:
    """The events the tests play: ``stab`` (a dot on ForearmL motor 2, 300 ms), ``buzz``
    (audio frames on ForearmR motor 4, 300 ms), ``mixed`` (both kinds: ForearmL motor 0 for
    300 ms and ForearmR motor 5 for 200 ms), ``long`` (ForearmL motor 1, 3 s) and ``vest``
    (VestFront only)."""
    return deployment(
        workspace,
        [
            mapping("stab", tact=[dot_project("ForearmL", 2, 300)], event_time=290),
            mapping("buzz", audio={"ForearmR": audio_frames(4, 100, 300 // FRAME_MS)}),
            mapping(
                "mixed",
                tact=[dot_project("ForearmL", 0, 300)],
                audio={"ForearmR": audio_frames(5, 100, 200 // FRAME_MS)},
            ),
            mapping("long", tact=[dot_project("ForearmL", 1, 3000)]),
            mapping("vest", tact=[dot_project("VestFront", 3, 500)]),
        ],
    )


def auth_init_library(workspace: str, haptic: dict[str, Any]) -> str:
    """``SdkRequestAuthInit`` as bHaptics' library 0.2.2 sends it."""
    authentication = {
        "ApplicationId": workspace,
        "ApplicationIdHashValue": "ab" * 64,
        "Cipher": "cd" * 80,
        "NonceHashValue": "ef" * 64,
        "SDKApiKey": "test-key",
    }
    message = {"authentication": json.dumps(authentication), "haptic": json.dumps(haptic)}
    return json.dumps({"Type": "SdkRequestAuthInit", "Message": json.dumps(message)})


def auth_init_game(workspace: str, haptic: dict[str, Any]) -> str:
    """``SdkRequestAuthInit`` as a real game sent it (lower-case envelope)."""
    authentication = {
        "cipher": "cd" * 80,
        "applicationId": workspace,
        "nonceHashValue": "ef" * 64,
        "applicationIdHashValue": "ab" * 64,
        "sdkApiKey": "test-key",
    }
    message = {"authentication": json.dumps(authentication), "haptic": json.dumps(haptic)}
    return json.dumps({"type": "SdkRequestAuthInit", "message": json.dumps(message)})
