"""Fair shares: who yields a slot when every slot is taken (``docs/owners.md``).

One rule for every pool of slots owners compete for: the engine's contact slots
(:class:`~phantomtouch.engine.owners.OwnerTable`), its pattern voices
(:meth:`~phantomtouch.engine.jobs.JobTable.admit`) and the OSC bridge's generic contacts
(:mod:`phantomtouch.osc.bridge`). An owner holding ``m`` asks for one slot more; the
largest other holders hold ``M``:

- if ``M >= m + 2``, one of them yields (the take evens the shares out; between owners one
  apart a take would only swap which of the two is short, and they would take the slot back
  and forth);
- if ``m == 0`` and ``M >= 1``, one of them yields too: a newcomer holding nothing always
  gets one slot, also when every holder holds one (then the slots pass round, oldest first);
- otherwise none yields and the ask is refused (``busy``).

Among the largest holders the caller lets the one whose slot is oldest yield its oldest slot
(voices: the oldest or the quietest, as the voice policy orders them).
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from typing import TypeVar

Owner = TypeVar("Owner", bound=Hashable)


def yielding(held: Mapping[Owner, int], owner: Owner) -> list[Owner]:
    """The owners one of whom yields a slot to ``owner`` under the rule above (host, any
    thread; pure).

    Parameters
    ----------
    held : mapping of owner to int, each >= 0
        Slots each owner holds now (``owner`` may be missing: it holds none).
    owner : hashable
        Who asks for one more slot.

    Returns
    -------
    list
        Every other owner holding the most, in ``held``'s order; empty: none yields.
    """
    mine = held.get(owner, 0)
    others = {other: count for other, count in held.items() if other != owner and count > 0}
    if not others:
        return []
    most = max(others.values())
    if most >= mine + 2 or mine == 0:
        return [other for other, count in others.items() if count == most]
    return []
