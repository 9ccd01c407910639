"""The status object the Player pushes to its clients, with its exact names.

::

    {"RegisteredKeys": ["Stab"], "ActiveKeys": ["Stab#2"], "ConnectedDeviceCount": 2,
     "ConnectedPositions": ["ForearmL", "ForearmR"],
     "Status": {"ForearmL": [0, 0, 100, 0, 0, 0], "ForearmR": [6 ints],
                "VestFront": [20 ints], "VestBack": [20 ints], "Head": [6 ints]}}

Every key is always there (the C++ SDK reads each with ``j.at(...)``, which throws on a
missing one), ``Status`` holds integer arrays 0-100 (the arms' six motors, the vest's
twenty per side, the head's six) and ``ConnectedPositions`` strings. Pure; any thread.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

MOTORS = {"ForearmL": 6, "ForearmR": 6, "VestFront": 20, "VestBack": 20, "Head": 6}
"""The positions of ``Status`` and their motor counts, in the order the Player sends them."""


def status_message(
    *,
    registered: Iterable[str],
    active: Iterable[str],
    positions: Sequence[str],
    levels: Mapping[str, Sequence[float]],
) -> dict[str, object]:
    """The status object.

    Parameters
    ----------
    registered, active : iterable of str
        The keys registered, and the names playing now (a key or its ``altKey``).
    positions : sequence of str
        The positions that play on the band (``ConnectedPositions``); their count is
        ``ConnectedDeviceCount``.
    levels : mapping of str to sequence of float
        Motor levels 0-100 by position (:data:`MOTORS`); a position missing is all 0, a
        level is rounded and clamped to 0-100, extra levels are dropped.
    """
    status: dict[str, list[int]] = {}
    for name, count in MOTORS.items():
        given = list(levels.get(name, ()))[:count]
        given += [0.0] * (count - len(given))
        status[name] = [min(100, max(0, round(level))) for level in given]
    return {
        "RegisteredKeys": sorted(registered),
        "ActiveKeys": sorted(active),
        "ConnectedDeviceCount": len(positions),
        "ConnectedPositions": list(positions),
        "Status": status,
    }
