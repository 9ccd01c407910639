"""Fair shares: who yields a slot when every slot is taken (``docs/owners.md``).

One rule for every pool of slots owners compete for: the engine's contact slots
(:class:`~phantomtouch.engine.owners.OwnerTable`), its pattern voices
(:meth:`~phantomtouch.engine.jobs.JobTable.admit`) and an input's connection slots
(:mod:`phantomtouch.service.admission`). Shares go first among **principals** (who a
source really is), then among the owners of one principal, so that opening more
connections or source ports buys a program nothing (as CPU shares go first among groups,
then among a group's processes). An owner's principal is the part of its name before
:data:`PRINCIPAL_SEPARATOR` (:func:`principal_of`; a name without one is a principal of
its own); the service names owners that way (``phantomtouch.service.admission``).

Between holders of one level, a holder with ``m`` asks for one slot more; the largest
other holders hold ``M``:

- if ``M >= m + 2``, one of them yields (the take evens the shares out; between holders one
  apart a take would only swap which of the two is short, and they would take the slot back
  and forth);
- if ``m == 0`` and ``M >= 1``, one of them yields too: a newcomer holding nothing always
  gets one slot, also when every holder holds one (then the slots pass round, oldest first);
- otherwise none yields.

The rule runs first over the principals' totals: when other principals yield, the owners
holding the most within those principals are the ones that yield. When no other principal
yields, it runs over the owners of the asker's own principal (a program's sources share
what the program holds). When neither yields, the ask is refused (``busy``).

Among the owners that yield the caller lets the one whose slot is oldest yield its oldest
slot (voices: the oldest or the quietest, as the voice policy orders them).
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from typing import TypeVar

Owner = TypeVar("Owner", bound=Hashable)

PRINCIPAL_SEPARATOR = "/"
"""An owner named ``PRINCIPAL/SOURCE`` belongs to the principal ``PRINCIPAL``."""


def principal_of(owner: object) -> object:
    """The principal of ``owner``: the part of its name before the first
    :data:`PRINCIPAL_SEPARATOR`, or the owner itself (a name without one, or an owner that
    is no string, such as None for jobs of no owner). Host, any thread; pure."""
    if isinstance(owner, str) and PRINCIPAL_SEPARATOR in owner:
        return owner.partition(PRINCIPAL_SEPARATOR)[0]
    return owner


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
        The owners that may yield, in ``held``'s order; empty: none yields.
    """
    mine = principal_of(owner)
    totals: dict[object, int] = {}
    for other, count in held.items():
        key = principal_of(other)
        totals[key] = totals.get(key, 0) + count
    givers = _yielding_flat(totals, mine)
    if givers:
        within = [o for o in held if principal_of(o) in givers and held[o] > 0]
        most = max(held[o] for o in within)
        return [o for o in within if held[o] == most]
    siblings = {o: count for o, count in held.items() if principal_of(o) == mine}
    return _yielding_flat(siblings, owner)


def _yielding_flat(held: Mapping[Owner, int], owner: Owner) -> list[Owner]:
    """The rule over one level of holders: every other holder holding the most, if one of
    them may yield to ``owner``."""
    mine = held.get(owner, 0)
    others = {other: count for other, count in held.items() if other != owner and count > 0}
    if not others:
        return []
    most = max(others.values())
    if most >= mine + 2 or mine == 0:
        return [other for other, count in others.items() if count == most]
    return []
