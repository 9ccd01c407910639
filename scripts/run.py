"""``python scripts/run.py [serve options]``: install once, then serve the touch API.

The same on Windows (PowerShell: ``py scripts\\run.py``), macOS and Linux: the service on
http://127.0.0.1:8000, playing on the first sound card with 8 outputs, else on the null
output. Arguments go to ``phantomtouch serve`` (``py scripts\\run.py --port 9000``).

When an install is needed and fails (no network after a ``git pull`` changed
``pyproject.toml``), it says so in one line and serves from the last good install in
``.venv``, which ``.venv/bin/phantomtouch serve`` also starts without trying to install.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from dotvenv import SERVICE_EXTRAS, InstallFailed, ensure, installed_before, python_of

OFFLINE_COMMAND = (
    r".venv\Scripts\phantomtouch serve"
    if sys.platform == "win32"
    else ".venv/bin/phantomtouch serve"
)
"""The last install's own command: it starts without looking at ``pyproject.toml``."""


def main() -> int:
    """Install if needed, then run ``phantomtouch serve`` with this script's arguments."""
    if sys.platform == "win32" and sys.version_info < (3, 12):
        print(
            f"scripts/run.py: Windows needs Python 3.12 or later (this is "
            f"{sys.version.split()[0]}): the engine's pipes are non-blocking only from 3.12 "
            "on; install it from python.org and run py -3.12 scripts\\run.py",
            file=sys.stderr,
        )
        return 1
    try:
        python = ensure(SERVICE_EXTRAS)
    except InstallFailed as exc:
        if not installed_before(SERVICE_EXTRAS):
            print(f"scripts/run: {exc}; nothing installed yet to start instead", file=sys.stderr)
            return 1
        python = python_of()
        print(
            f"scripts/run: {exc}; starting the last good install "
            f"(offline: {OFFLINE_COMMAND} starts it without trying to install)",
            file=sys.stderr,
        )
    command = [str(python), "-m", "phantomtouch", "serve", *sys.argv[1:]]
    if sys.platform == "win32":  # no exec on Windows: wait, and pass its status on
        try:
            return subprocess.call(command)
        except KeyboardInterrupt:
            return 0
    os.execv(command[0], command)  # the service gets this process and its signals


if __name__ == "__main__":
    sys.exit(main())
