"""Imported by every interpreter started with this folder on ``PYTHONPATH``: the modules
and ``os`` functions that exist on POSIX systems only are made unavailable, as on Windows.

An import of one of :data:`POSIX_ONLY_MODULES` raises ``ModuleNotFoundError``; the
functions in :data:`POSIX_ONLY_OS_FUNCTIONS` are removed from ``os``. Functions the
standard library itself calls on Linux to start a process or a thread (``os.fork``,
``os.waitpid``, ``os.pipe`` ...) stay, since they have Windows counterparts behind the
same standard-library calls. ``select.select`` raises ``OSError`` for anything but a
socket, as Windows' does (WinError 10038). ``os.read``, ``os.write`` and
``os.set_blocking`` raise ``OSError(EBADF)`` on a pipe, as on Windows, where a
``multiprocessing`` ``Connection``'s ``fileno()`` is a pipe handle and not a file
descriptor; the ``multiprocessing`` package itself may still call them, since on Linux it
reads and writes its own pipes with them where Windows has its handle calls. When
``PHANTOMTOUCH_WINDOWS_LIKE_MARKS`` names a folder, each interpreter writes a file named
by its process id there, so a test can tell that the server and its engine process both
ran this way.
"""

from __future__ import annotations

import errno
import importlib.abc
import os
import select
import stat
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any

POSIX_ONLY_MODULES = frozenset(
    {"fcntl", "termios", "tty", "pty", "resource", "pwd", "grp", "syslog", "posix_ipc"}
)
POSIX_ONLY_OS_FUNCTIONS = (
    "sched_setscheduler",
    "sched_getscheduler",
    "sched_param",
    "sched_setaffinity",
    "sched_getaffinity",
    "getuid",
    "geteuid",
    "getgid",
    "getegid",
    "getgroups",
    "setuid",
    "setgid",
    "setsid",
    "getsid",
    "setpgid",
    "getpgid",
    "killpg",
    "nice",
    "getpriority",
    "setpriority",
    "mlockall",
    "munlockall",
    "sync",
    "chown",
    "lchown",
    "fchown",
    "mkfifo",
    "mknod",
    "getloadavg",
    "ttyname",
    "openpty",
    "forkpty",
)


class _Refuse(importlib.abc.MetaPathFinder):
    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> None:
        if fullname.partition(".")[0] in POSIX_ONLY_MODULES:
            raise ModuleNotFoundError(f"No module named {fullname!r}", name=fullname)
        return None


WSAENOTSOCK = 10038
_select = select.select


def _fd(item: Any) -> int:
    return item if isinstance(item, int) else int(item.fileno())


def _select_sockets_only(
    rlist: Any, wlist: Any, xlist: Any, timeout: float | None = None
) -> tuple[list[Any], list[Any], list[Any]]:
    """``select.select`` as on Windows: it takes sockets only."""
    for item in (*rlist, *wlist, *xlist):
        if not stat.S_ISSOCK(os.fstat(_fd(item)).st_mode):
            raise OSError(
                WSAENOTSOCK, "An operation was attempted on something that is not a socket"
            )
    return _select(rlist, wlist, xlist, timeout)


def _pipes_refused(function: Any) -> Any:
    """``function`` (of a file descriptor first) refusing a pipe unless the caller is in
    the ``multiprocessing`` package."""

    def refusing(fd: int, *args: Any) -> Any:
        caller = sys._getframe(1).f_globals.get("__name__") or ""
        if not caller.startswith("multiprocessing.") and _is_pipe(fd):
            raise OSError(errno.EBADF, "Bad file descriptor (a pipe handle on Windows)")
        return function(fd, *args)

    return refusing


def _is_pipe(fd: int) -> bool:
    try:
        return stat.S_ISFIFO(os.fstat(fd).st_mode)
    except OSError:
        return False


select.select = _select_sockets_only
os.read = _pipes_refused(os.read)
os.write = _pipes_refused(os.write)
os.set_blocking = _pipes_refused(os.set_blocking)
for _name in POSIX_ONLY_MODULES:
    sys.modules.pop(_name, None)
sys.meta_path.insert(0, _Refuse())
for _function in POSIX_ONLY_OS_FUNCTIONS:
    if hasattr(os, _function):
        delattr(os, _function)

_marks = os.environ.get("PHANTOMTOUCH_WINDOWS_LIKE_MARKS")
if _marks:
    with open(os.path.join(_marks, str(os.getpid())), "w", encoding="utf-8") as _mark:
        _mark.write(" ".join(sys.argv))
