"""A ``frame`` submit as live contacts on the band: where its points land and how they glide.

A frame's points land where the arm map puts them, by the same rule as a registered
project's (:func:`phantomtouch.clips.tact_score.frame_score`): each distinct place one
phantom at the largest intensity there, a dot at its motor's place in the layout (the
first Tactosy's 20-motor layout for legacy ``Left``/``Right``), a path point at exactly its
``(x, y)``. Here each place becomes a live contact rather than a scheduled voice, so that
a game moving a point by re-sending it glides: a new frame of the same key moves the
contacts its previous frame put down (nothing restarts); contacts it no longer needs lift
off, new ones touch down. Positions the band does not play (vest, head, hands, feet, an
arm left out of the map) give no contact. Host, the event loop.
"""

from __future__ import annotations

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
    from phantomtouch.engine import EngineFront
    from phantomtouch.schema import DeviceProfile


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
        [(d.index, d.intensity / MAX_INTENSITY) for d in frame.dots],
        [(p.x, p.y, p.intensity / MAX_INTENSITY) for p in frame.paths],
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
    if layout is None:
        return levels.combined(
            ((p.x, p.y, p.intensity) for p in frame.paths),
            ((d.index, d.intensity) for d in frame.dots),
        )
    dots = [(*layout[d.index], d.intensity) for d in frame.dots if d.index in layout]
    return levels.combined([*((p.x, p.y, p.intensity) for p in frame.paths), *dots])


class FramePlayback:
    """The contacts of one key's frames, held by ``owner`` in the engine's front.

    Parameters
    ----------
    engine : EngineFront
    owner : str
        The connection's owner id.
    prefix : str
        This key's contact ids start with it (unique within the owner).
    arm_map : ArmMap
    deadline_s : float
        The contacts' deadline in the front (renewed by the connection while it lives).
    """

    def __init__(
        self, engine: EngineFront, owner: str, prefix: str, arm_map: ArmMap, deadline_s: float
    ) -> None:
        self.engine = engine
        self.owner = owner
        self.prefix = prefix
        self.arm_map = arm_map
        self.deadline_s = deadline_s
        self.frame: Frame | None = None
        self._held: list[str] = []

    @property
    def held(self) -> list[str]:
        """The contact ids this key holds down (as far as it knows)."""
        return list(self._held)

    def forget(self, contacts: Sequence[str]) -> None:
        """The front let go of ``contacts``: they are no longer this key's to move or lift."""
        self._held = [c for c in self._held if c not in contacts]

    def play(self, frame: Frame, spots: Sequence[Spot]) -> None:
        """Show ``frame`` at ``spots``: move the contacts down, put new ones down, lift
        those left over (event loop).

        Raises
        ------
        PhantomTouchError
            The engine refused a contact (busy, closed); those placed stay.
        """
        self.frame = frame
        held, self._held = self._held, []
        for k, spot in enumerate(spots):
            contact = f"{self.prefix}-{k}"
            if contact in held:
                try:
                    self.engine.contact_move(
                        self.owner, contact, spot.x_cm, spot.y_cm, intensity=spot.intensity
                    )
                    self._held.append(contact)
                    continue
                except ProtocolError:  # let go of meanwhile (a stop, a deadline): down again
                    pass
            self.engine.contact_down(
                self.owner,
                contact,
                spot.x_cm,
                spot.y_cm,
                intensity=spot.intensity,
                carrier=self.arm_map.carrier,
                law=self.arm_map.law,
                deadline_s=self.deadline_s,
            )
            self._held.append(contact)
        for contact in held:
            if contact not in self._held:
                self.engine.contact_up(self.owner, contact)

    def stop(self) -> None:
        """Lift every contact of the key (event loop; never refused)."""
        held, self._held = self._held, []
        for contact in held:
            self.engine.contact_up(self.owner, contact)
