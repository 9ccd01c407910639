"""Haptic clip import: Meta Haptics Studio ``.haptic`` and Apple Core Haptics ``.ahap``.

Each format becomes a :class:`~phantomtouch.schema.HapticClip` (amplitude and frequency
envelopes, transients), played as a pattern's carrier. Modules:
:mod:`~phantomtouch.clips.haptic_file` (``.haptic``), :mod:`~phantomtouch.clips.ahap`
(``.ahap``), :mod:`~phantomtouch.clips.load` (a file of either, by its suffix or content)
and :mod:`~phantomtouch.clips.command` (``phantomtouch import``). Only the schema is
imported here.
"""

from phantomtouch.clips.load import load_clip, parse_clip

__all__ = ["load_clip", "parse_clip"]
