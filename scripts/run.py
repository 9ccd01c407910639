"""``python scripts/run.py [serve options]``: install once, then serve the touch API.

The same on Windows (PowerShell: ``py scripts\\run.py``), macOS and Linux: the service on
http://127.0.0.1:8000, playing on the first sound card with 8 outputs, else on the null
output. Arguments go to ``phantomtouch serve`` (``py scripts\\run.py --port 9000``).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from dotvenv import SERVICE_EXTRAS, ensure


def main() -> int:
    """Install if needed, then run ``phantomtouch serve`` with this script's arguments."""
    try:
        python = ensure(SERVICE_EXTRAS)
    except subprocess.CalledProcessError as exc:
        print(f"scripts/run: installing failed (exit {exc.returncode})", file=sys.stderr)
        return 1
    command = [str(python), "-m", "phantomtouch", "serve", *sys.argv[1:]]
    if sys.platform == "win32":  # no exec on Windows: wait, and pass its status on
        try:
            return subprocess.call(command)
        except KeyboardInterrupt:
            return 0
    os.execv(command[0], command)  # the service gets this process and its signals


if __name__ == "__main__":
    sys.exit(main())
