"""Open files of the service process: the limit raised at start, the connection budget.

Every connection costs one file descriptor; when the process has none left, ``accept``
fails and the server stops accepting anyone, the holder of the token and its ``POST
/stop`` included. At start :func:`raise_open_file_limit` raises the soft limit to the
hard one (1,024 is the soft default of many Linux desktops, 256 of macOS; Windows has no
such limit). :meth:`ConnectionBudget.plan` then splits what is left once the service's
own files are open:

- ``connections``: HTTP and WebSocket connections served as usual;
- ``stop_lane``: a few more, beyond the budget, that serve ``POST /stop`` only (anything
  else is answered 503 and closed), with a short header deadline;
- ``backlog``: what the listening socket may queue, and what the event loop accepts in
  one go before the server has looked at any of them (each is a descriptor meanwhile);
- the rest: headroom for the files the service opens while it runs (the pattern
  library, a capture WAV, the engine's pipes, a fleet connection).

A connection beyond ``connections + stop_lane`` is closed as soon as it is accepted, so
the process never runs out of descriptors; the lane keeps one door open for the stop.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

UNLIMITED = 1 << 20
"""What an open-file limit of "unlimited" counts as (more than any budget needs)."""
STOP_LANE = 16
"""Connections beyond the budget that may ask for ``POST /stop``, over two of the event
loop's accept bursts (:meth:`ConnectionBudget.plan`)."""
HEADROOM = 64
"""Descriptors kept for the files the service opens while it runs."""
MAX_BACKLOG = 2048
"""uvicorn's own backlog: the most connections the listening socket queues."""


def raise_open_file_limit() -> tuple[int, int] | None:
    """Raise this process's soft open-file limit to its hard limit (main thread, at start).

    Returns
    -------
    (before, after) : tuple of int
        The soft limit before and after (``after`` is ``before`` when the system refused
        or it was at the hard limit already); None where the system has no such limit
        (Windows: sockets are not bounded by it).
    """
    if sys.platform == "win32":  # sockets are not bounded by an open-file limit there
        return None
    try:
        import resource
    except ImportError:  # a platform without it
        return None

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = hard
    if sys.platform == "darwin":  # macOS refuses more than OPEN_MAX for an unlimited hard
        target = min(hard if hard != resource.RLIM_INFINITY else UNLIMITED, 10_240)
    if target == resource.RLIM_INFINITY:
        target = UNLIMITED
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        except (ValueError, OSError):
            return soft, soft
        return soft, target
    return (UNLIMITED, UNLIMITED) if soft == resource.RLIM_INFINITY else (soft, soft)


def descriptors_in_use() -> int | None:
    """How many descriptors this process has open (Linux, macOS); None elsewhere."""
    for folder in ("/proc/self/fd", "/dev/fd"):
        if Path(folder).is_dir():
            try:
                return len(os.listdir(folder)) - 1  # the listing's own descriptor
            except OSError:
                return None
    return None


@dataclass(frozen=True)
class ConnectionBudget:
    """How the open-file limit is shared (module docstring); ``limit`` None: no limit."""

    limit: int | None
    connections: int
    stop_lane: int
    backlog: int

    @classmethod
    def plan(cls, limit: int | None, in_use: int | None) -> ConnectionBudget:
        """The budget under ``limit`` descriptors with ``in_use`` open already.

        Parameters
        ----------
        limit : int or None
            The soft open-file limit (after :func:`raise_open_file_limit`); None: the
            system sets none (Windows), and the budget is that of :data:`UNLIMITED`.
        in_use : int or None
            Descriptors open now (:func:`descriptors_in_use`); None: assumed 64.
        """
        usable = (limit if limit is not None else UNLIMITED) - (in_use or 64) - HEADROOM
        backlog = max(8, min(MAX_BACKLOG, usable // 8))
        # The event loop accepts up to ``backlog`` connections at once before it reads
        # any, and each newcomer of a full lane closes the lane's oldest: a lane of two
        # bursts and more keeps a stop accepted in one burst through the next, until
        # its request, sent whole with its connection, is read.
        lane = STOP_LANE + 2 * backlog
        connections = max(1, usable - backlog - lane)
        return cls(limit, connections, lane, backlog)

    def describe(self) -> str:
        """One line for the start-up log."""
        limit = "no open-file limit" if self.limit is None else f"{self.limit} open files"
        return (
            f"{limit}: {self.connections} connections at once, {self.stop_lane} more for "
            "POST /stop only"
        )
