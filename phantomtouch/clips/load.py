"""Read a ``.haptic`` or ``.ahap`` file (or its text) into a clip; refusals name the field."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Literal

from pydantic import ValidationError

from phantomtouch.clips.files import read_limited
from phantomtouch.errors import ParameterError
from phantomtouch.schema.clip import HapticClip
from phantomtouch.schema.validation import describe_validation_error

ClipFormat = Literal["haptic", "ahap"]


class ClipWarning(UserWarning):
    """Part of a clip file the engine does not play (an audio event, say): the clip is
    made of the rest, and the warning's one line names the part by its path in the file."""


MAX_FILE_BYTES = 16 << 20
"""Largest clip file read, bytes."""
CLIP_DEPTH = 6
"""How deep an ``.ahap`` file's arrays and objects nest (``.haptic``: 5). Deeper JSON is
read up to the interpreter's recursion limit and refused beyond, in one line."""


def detect_format(document: Any, suffix: str = "") -> ClipFormat:
    """``haptic`` or ``ahap``, from the file's suffix, else from its top-level keys."""
    known = _suffix_format(suffix)
    if known is not None:
        return known
    if isinstance(document, dict):
        if "Pattern" in document:
            return "ahap"
        if "signals" in document:
            return "haptic"
    raise ParameterError(
        "not a haptic clip: a .haptic file has 'signals', an .ahap file 'Pattern' at its top "
        f"level; got {sorted(document) if isinstance(document, dict) else type(document).__name__}"
    )


def parse_clip(text: str | bytes, *, suffix: str = "", source: str = "clip") -> HapticClip:
    """The clip a ``.haptic`` or ``.ahap`` document describes.

    Parameters
    ----------
    text : str or bytes
        The file's JSON.
    suffix : str
        The file's suffix (``.haptic``, ``.ahap``); other or none: told by the content.
    source : str
        What to call the file in messages.

    Raises
    ------
    ParameterError
        Not JSON (or nested deeper than the interpreter reads), not either format, or a
        field outside its range; the message names the field by its path in the file
        (``signals.continuous.envelopes.amplitude[2].time``).

    Warns
    -----
    ClipWarning
        Parts of an ``.ahap`` file the engine does not play (audio events, dynamic
        parameters other than intensity and sharpness), named by their path.
    """
    from phantomtouch.clips.ahap import clip_of_ahap
    from phantomtouch.clips.ahap_schema import AHAP_FILE
    from phantomtouch.clips.haptic_file import HapticFile, clip_of_haptic

    kind = _suffix_format(suffix)
    try:
        if kind is not None:
            # The bytes straight into pydantic-core: one pass, no Python object per event.
            try:
                if kind == "haptic":
                    return clip_of_haptic(HapticFile.model_validate_json(text))
                return clip_of_ahap(AHAP_FILE.validate_json(text), source=source)
            except ValidationError as exc:
                if exc.errors()[0]["type"] != "json_invalid":
                    raise
                # What pydantic-core's reader does not take (deeper than its 200 levels,
                # UTF-16, lone surrogates) is read as ``json.loads`` reads it, below.
        document = _loaded(text, source)
        kind = detect_format(document, suffix)
        if kind == "haptic":
            return clip_of_haptic(HapticFile.model_validate(document))
        return clip_of_ahap(AHAP_FILE.validate_python(document), source=source)
    except ValidationError as exc:
        raise ParameterError(f"{source} (.{kind}): {describe_validation_error(exc)}") from exc


def _suffix_format(suffix: str) -> ClipFormat | None:
    suffix = suffix.lower().lstrip(".")
    if suffix in ("haptic", "ahap"):
        return suffix  # type: ignore[return-value]
    return None


def _loaded(text: str | bytes, source: str) -> Any:
    try:
        return json.loads(text)
    except ValueError as exc:
        raise ParameterError(f"{source}: not JSON ({exc})") from exc
    except RecursionError:
        raise ParameterError(
            f"{source}: JSON nested deeper than {sys.getrecursionlimit()} levels (max_depth; "
            f"a clip file nests {CLIP_DEPTH})"
        ) from None


def load_clip(path: str | Path) -> HapticClip:
    """Read a clip file (see :func:`parse_clip`); unreadable files are ParameterError too."""
    path = Path(path)
    data = read_limited(path, max_bytes=MAX_FILE_BYTES, what="a clip file")
    return parse_clip(data, suffix=path.suffix, source=path.name)
