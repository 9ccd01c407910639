"""What the machine and the service spend, for ``bench_realtime.py``, read from ``/proc``.

- :func:`cpu_seconds`: CPU time of the whole machine and of this process tree, to tell how
  much of it other programs took during a scenario;
- :func:`rss_bytes`, :func:`engine_pid`: the memory of the service and its engine process.
"""

from __future__ import annotations

import os
from pathlib import Path


def cpu_seconds() -> tuple[float, float]:
    """CPU seconds spent so far by the whole machine and by this process and its descendants.

    The machine's figure is every core's busy time (``/proc/stat`` without idle and
    iowait); the tree's counts live descendants (the service, its engine process, JACK)
    and, through ``cutime``/``cstime``, the children already waited for (hogs, wrk).
    """
    tick_s = 1.0 / os.sysconf("SC_CLK_TCK")
    ticks = [int(t) for t in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    machine_s = (sum(ticks) - ticks[3] - ticks[4]) * tick_s
    parents: dict[int, int] = {}
    spent: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        pid = int(entry.name)
        parents[pid] = int(fields[1])
        spent[pid] = sum(int(f) for f in fields[11:15])  # utime stime cutime cstime
    tree, frontier = set(), [os.getpid()]
    while frontier:
        pid = frontier.pop()
        tree.add(pid)
        frontier += [child for child, parent in parents.items() if parent == pid]
    return machine_s, sum(spent.get(pid, 0) for pid in tree) * tick_s


def rss_bytes(pid: int) -> int | None:
    """Resident memory of a process, bytes (``VmRSS``), or None when it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def engine_pid(server_pid: int) -> int | None:
    """The engine process of a service: its child started by ``multiprocessing`` spawn
    (not the resource tracker, its other child), or None."""
    for task in Path(f"/proc/{server_pid}/task").glob("*"):
        try:
            children = [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue
        for child in children:
            try:
                command = Path(f"/proc/{child}/cmdline").read_bytes()
            except OSError:
                continue
            if b"spawn_main" in command:
                return child
    return None
