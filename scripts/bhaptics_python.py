"""Fetch bHaptics' own SDK2 client library for the tests: ``python scripts/bhaptics_python.py``.

``bhaptics-python`` 0.2.0 (PyPI, MIT) is the client that ``tests/bhaptics/sdk2`` drive
against a real ``phantomtouch serve``. Its Linux wheels exist for CPython 3.10-3.12 only,
tagged ``manylinux_2_34_x86_64``, and bundle an OpenSSL built against glibc 2.38; on an older
glibc (Debian 12 has 2.36) the extension loads once both bundled libraries are replaced by
the system's ``libssl.so.3``/``libcrypto.so.3`` (``patchelf``, a Debian package).

This script (run by ``scripts/install --dev``) finds a CPython 3.10-3.12 (this one, or
``python3.12``/``python3.11``/``python3.10`` on PATH), downloads the wheel for it with pip,
unpacks it into ``.cache/bhaptics-python/site``, patches it, checks that it imports, and
writes the interpreter's path to ``.cache/bhaptics-python/python.txt``: the tests then need
no network. On a platform other than Linux x86-64 it says so and does nothing. Exit 0
when the cache is ready (or the platform has none), 1 when it could not be made.
"""

from __future__ import annotations

import platform
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / ".cache" / "bhaptics-python"
VERSION = "0.2.0"
PYTHONS = ("python3.12", "python3.11", "python3.10")
SYSTEM_LIBS = {"libssl": "libssl.so.3", "libcrypto": "libcrypto.so.3"}


def interpreter() -> tuple[str, str] | None:
    """A CPython the wheel has a build for: (path, "3.X"), or None."""
    candidates = [sys.executable, *filter(None, (shutil.which(name) for name in PYTHONS))]
    for path in candidates:
        found = subprocess.run(
            [path, "-c", "import sys; print(f'{sys.version_info[0]}.{sys.version_info[1]}')"],
            capture_output=True,
            text=True,
            check=False,
        ).stdout.strip()
        if found in ("3.10", "3.11", "3.12"):
            return path, found
    return None


def ready() -> bool:
    """Whether the cache holds a library that imports."""
    marker = CACHE / "python.txt"
    if not marker.exists():
        return False
    python = marker.read_text(encoding="utf-8").strip()
    check = [python, "-c", "import bhaptics_python"]
    env = {"PYTHONPATH": str(CACHE / "site"), "PATH": "/usr/bin:/bin"}
    return subprocess.run(check, env=env, capture_output=True, check=False).returncode == 0


def main() -> int:
    """Make the cache (see the module docstring)."""
    if sys.platform != "linux" or platform.machine() != "x86_64":
        print("bhaptics_python: the SDK2 client's tests run on Linux x86-64 only; skipped")
        return 0
    if ready():
        print(f"bhaptics_python: {CACHE} is ready")
        return 0
    found = interpreter()
    if found is None:
        print(
            "bhaptics_python: no CPython 3.10-3.12 found (bhaptics-python has no wheel for others)",
            file=sys.stderr,
        )
        return 1
    if shutil.which("patchelf") is None:
        print(
            "bhaptics_python: patchelf is missing (apt-get install patchelf; "
            "scripts/apt-packages.txt)",
            file=sys.stderr,
        )
        return 1
    python, version = found
    with tempfile.TemporaryDirectory() as folder:
        download = [
            sys.executable,
            "-m",
            "pip",
            "download",
            "--quiet",
            "--no-deps",
            "--only-binary=:all:",
            "--platform",
            "manylinux_2_34_x86_64",
            "--python-version",
            version,
            "-d",
            folder,
            f"bhaptics-python=={VERSION}",
        ]
        if subprocess.run(download, check=False).returncode != 0:
            print("bhaptics_python: pip could not download the wheel", file=sys.stderr)
            return 1
        wheel = next(Path(folder).glob("*.whl"))
        shutil.rmtree(CACHE, ignore_errors=True)
        with zipfile.ZipFile(wheel) as archive:
            archive.extractall(CACHE / "site")
    for extension in (CACHE / "site" / "bhaptics_python").glob("*.so"):
        needed = subprocess.run(
            ["patchelf", "--print-needed", str(extension)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split()
        for library in needed:
            for stem, system in SYSTEM_LIBS.items():
                if library.startswith(stem + "-"):
                    subprocess.run(
                        ["patchelf", "--replace-needed", library, system, str(extension)],
                        check=True,
                    )
    (CACHE / "python.txt").write_text(python + "\n", encoding="utf-8")
    if not ready():
        print(f"bhaptics_python: the library in {CACHE} does not import", file=sys.stderr)
        return 1
    print(f"bhaptics_python: bhaptics-python {VERSION} ready in {CACHE} for {python}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
