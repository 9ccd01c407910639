"""A thread that must answer at once (an input's receiving thread) asks for real-time priority.

On Linux an unprivileged user may run a thread ``SCHED_RR`` up to the priority its
``RLIMIT_RTPRIO`` allows (``ulimit -r``; PAM's ``limits.conf`` gives the ``audio`` group
one, and rtkit grants the same to a desktop session's threads). Such a thread runs as soon
as its datagram arrives, ahead of every ordinary process however busy the machine is.
``SCHED_RESET_ON_FORK`` keeps it from passing to the threads and processes the thread starts
(a worker it starts, the engine front's deadline thread, run at ordinary priority). Elsewhere, or
without the permission, the thread keeps its ordinary priority and the reason is logged.
"""

from __future__ import annotations

import logging
import os
import sys

from phantomtouch.engine.process import REALTIME_PRIORITY

logger = logging.getLogger("phantomtouch.service")

INPUT_PRIORITY = REALTIME_PRIORITY
"""``SCHED_RR`` priority of input threads: the engine process's own (the lowest real-time
one), so neither starves the other."""


def raise_thread_priority(name: str, priority: int = INPUT_PRIORITY) -> bool:
    """Run the calling thread ``SCHED_RR`` at ``priority`` (1-99); whether it does now.

    Called by the thread itself, first thing (any input's thread). ``name`` says whose
    thread it is in the log line of a refusal.
    """
    if sys.platform != "linux" or not hasattr(os, "sched_setscheduler"):
        return False
    try:
        policy = os.SCHED_RR | os.SCHED_RESET_ON_FORK
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except OSError as exc:
        logger.info("%s keeps ordinary priority (ulimit -r allows none): %s", name, exc)
        return False
    return True
