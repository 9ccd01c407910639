"""The threads that read live contacts run at real-time priority where the user may ask for it.

A real ``phantomtouch serve --osc --bhaptics`` is started; its threads' scheduling policies
are read from ``/proc``. Where this test's own thread may run ``SCHED_RR`` (``ulimit -r``, or
root), the server's three input threads (the contact lane, the OSC bridge, the bHaptics
stand-in) must run so, and no other thread of the server's process may: the event loop and
the workers keep their ordinary priority, the front's deadline thread too when an input's
thread starts it. Linux only (``/proc``, ``SCHED_RR``).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

import pytest
from pythonosc.udp_client import SimpleUDPClient

from tests.support.live_server import HOST, LiveServer, free_ports

SCHED_RR = 2
"""``policy`` in ``/proc/PID/task/TID/stat`` (field 41) of a ``SCHED_RR`` thread."""


def may_run_round_robin() -> bool:
    """Whether a thread of this process may switch itself to ``SCHED_RR`` priority 1."""
    allowed: list[bool] = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(1))
        except OSError:
            allowed.append(False)
        else:
            allowed.append(True)

    thread = threading.Thread(target=attempt)
    thread.start()
    thread.join()
    return allowed[0]


def policies(pid: int) -> list[int]:
    """The scheduling policy of every thread of ``pid``."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        found.append(int(fields[38]))  # field 41 of the whole line, counted from 1
    return found


@pytest.mark.skipif(sys.platform != "linux", reason="thread policies are read from /proc")
def test_the_input_threads_and_only_they_run_round_robin(tmp_path: Path) -> None:
    if not may_run_round_robin():
        pytest.skip("this user may not run SCHED_RR threads (ulimit -r is 0)")
    osc_port, bhaptics_port = free_ports(2)
    args = ("--osc", f"{HOST}:{osc_port}", "--bhaptics", f"{HOST}:{bhaptics_port}")
    with LiveServer(tmp_path / "p.db", args=args) as server:
        assert server.process is not None
        pid = server.process.pid
        started = len(policies(pid))
        # An OSC contact: its deadline starts the front's deadline thread from the OSC
        # bridge's thread, which must not pass its priority on.
        SimpleUDPClient(HOST, osc_port).send_message("/phantomtouch/contact/a", [1.9, 5.0, 0.5])
        deadline = time.monotonic() + 10.0
        while len(found := policies(pid)) == started and time.monotonic() < deadline:
            time.sleep(0.05)
    assert found.count(SCHED_RR) == 3, found
