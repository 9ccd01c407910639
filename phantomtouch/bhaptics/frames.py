"""A ``frame`` submit as live contacts on the band: where its points land and how they glide.

A frame's points land where the arm map puts them, by the same rule as a registered
project's (:func:`phantomtouch.clips.tact_score.frame_score`): each distinct place one
phantom at the largest intensity there, a dot at its motor's place in the layout (the
first Tactosy's 20-motor layout for legacy ``Left``/``Right``), a path point at exactly its
``(x, y)``. Here each place becomes a live contact rather than a scheduled voice, so that
a game moving a point by re-sending it glides: a new frame of the same key moves the
contacts its previous frame put down (nothing restarts); contacts it no longer needs lift
off, new ones touch down. Positions the band does not play (vest, head, hands, feet, an
arm left out of the map) give no contact. The contacts are the connection's, through its
admission handle: the engine's owner table is the one record of which are down, and they
end one deadline after the connection's last message, however long the frame. The frame is
on show under its key in the handle's named plays
(:class:`~phantomtouch.service.admission.NamedPlays`), with the prefix of its contacts' ids
(:func:`frame_prefix`): its end, a stop or ``turnOff`` lifts them there. Host, the event
loop.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.bhaptics import levels
from phantomtouch.bhaptics.requests import MAX_INTENSITY, Frame
from phantomtouch.clips.tact import LEGACY_TACTOSY_LAYOUT
from phantomtouch.clips.tact_score import frame_score
from phantomtouch.errors import ProtocolError
from phantomtouch.schema.pattern import KeyframePath

if TYPE_CHECKING:
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.schema import DeviceProfile
    from phantomtouch.service.admission import Handle


@dataclass(frozen=True)
class Spot:
    """One phantom of a frame: band place, cm, and intensity 0-1 of the device's max."""

    x_cm: float
    y_cm: float
    intensity: float


def frame_spots(
    frame: Frame, arm_map: ArmMap, device: DeviceProfile, *, max_spots: int
) -> list[Spot]:
    """Where ``frame`` is felt on the band, its ``max_spots`` strongest places; empty for a
    position the band does not play or a frame without a point above 0."""
    placed = frame_score(
        frame.position,
        [(d.index, d.intensity) for d in frame.dots],
        [(p.x, p.y, p.intensity) for p in frame.paths],
        frame.duration_ms,
        arm_map,
        device,
        layout=LEGACY_TACTOSY_LAYOUT if frame.legacy else None,
    )
    spots = []
    for voice in placed.voices:
        path, scale = voice.pattern.path, voice.pattern.intensity
        if isinstance(path, KeyframePath) and isinstance(scale, float):  # a frame's stand still
            first = path.keyframes[0]
            spots.append(Spot(first.x_cm, first.y_cm, scale * first.intensity))
    spots.sort(key=lambda spot: -spot.intensity)
    return spots[:max_spots]


def frame_levels(frame: Frame) -> list[float]:
    """The six equivalent motor levels 0-100 of ``frame`` on its own position."""
    layout = LEGACY_TACTOSY_LAYOUT if frame.legacy else None
    paths = [(p.x, p.y, p.intensity * MAX_INTENSITY) for p in frame.paths]
    if layout is None:
        return levels.combined(paths, ((d.index, d.intensity * MAX_INTENSITY) for d in frame.dots))
    dots = [
        (*layout[d.index], d.intensity * MAX_INTENSITY) for d in frame.dots if d.index in layout
    ]
    return levels.combined([*paths, *dots])


def frame_prefix(name: str) -> str:
    """The contact ids of the frames of key ``name`` start with this (a digest of the name:
    any key gives a short id of its own, and nothing is kept to remember it)."""
    return "f" + hashlib.blake2b(name.encode("utf-8", "surrogatepass"), digest_size=6).hexdigest()


def frame_contacts(handle: Handle, name: str) -> list[str]:
    """The contacts the frames of key ``name`` hold down now (the front's owner table)."""
    prefix = frame_prefix(name) + "-"
    return [c for c in handle.contacts() if c.startswith(prefix)]


def show_frame(handle: Handle, name: str, spots: Sequence[Spot], arm_map: ArmMap) -> None:
    """Show a frame of key ``name`` at ``spots`` (host, the event loop): the contacts its
    previous frame holds move, new ones touch down (with the handle's deadline), those left
    over lift.

    Raises
    ------
    PhantomTouchError
        The admission or the engine refused a contact (the owner's contacts, a busy
        engine); those placed stay.
    """
    prefix = frame_prefix(name)
    held = frame_contacts(handle, name)
    wanted = [f"{prefix}-{k}" for k in range(len(spots))]
    for contact in held:
        if contact not in wanted:
            handle.up(contact)
    for contact, spot in zip(wanted, spots, strict=True):
        if contact in held:
            try:
                handle.move(contact, spot.x_cm, spot.y_cm, intensity=spot.intensity)
                continue
            except ProtocolError:  # let go of meanwhile (a stop, a deadline): down again
                pass
        handle.down(
            contact,
            spot.x_cm,
            spot.y_cm,
            intensity=spot.intensity,
            carrier=arm_map.carrier,
            law=arm_map.law,
        )
