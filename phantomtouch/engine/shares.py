"""Fair shares: who yields a slot when every slot is taken; the rule, its reasons and
where each pool uses it are in ``docs/owners.md`` (Fair shares).

One rule for every pool of slots owners compete for: the engine's contact slots
(:class:`~phantomtouch.engine.owners.OwnerTable`), its pattern voices
(:meth:`~phantomtouch.engine.jobs.JobTable.admit`) and an input's connection slots
(:mod:`phantomtouch.service.admission`). It runs first over the principals' totals (an
owner's principal: :func:`principal_of`; in a principal that yields, its owners holding the
most yield), then, when none does, over the owners of the asker's own principal. At one
level, a holder with ``m`` asks for one slot more and the largest other holders hold ``M``:
one of them yields if ``M >= m + 2``, or if ``m == 0`` and ``M >= 1`` (a newcomer always
gets one); otherwise none does, and the ask is refused (``busy``). The caller picks which
of them yields (the one whose slot is oldest; voices: as the voice policy orders them).
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
