"""Haptic clip import: Meta Haptics Studio ``.haptic`` and Apple Core Haptics ``.ahap``.

Each format becomes a :class:`~phantomtouch.schema.HapticClip` (amplitude and frequency
envelopes, transients), played as a pattern's carrier. Modules:
:mod:`~phantomtouch.clips.haptic_file` (``.haptic``), :mod:`~phantomtouch.clips.ahap`
(``.ahap``) and :mod:`~phantomtouch.clips.load` (a file of either, by its suffix or
content): a file in, a clip out. Only the schema (and the exception root) is imported here;
storing a clip is the library's (:mod:`phantomtouch.service.store`), and ``phantomtouch
import`` is :mod:`phantomtouch.commands.import_file`.
"""

from phantomtouch.clips.load import ClipWarning, load_clip, parse_clip

__all__ = ["ClipWarning", "load_clip", "parse_clip"]
