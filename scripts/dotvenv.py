"""The project's virtual environment, ``.venv``, installed once and again only when needed.

``python scripts/run.py`` and ``python scripts/test.py`` (Windows, macOS and Linux alike;
``scripts/run`` and ``scripts/test`` on Linux and macOS) make ``.venv`` with the extras
they need and write a stamp into it: the SHA-256 of ``pyproject.toml`` and the extras
installed. Later starts compare the stamp and install nothing when it matches, so they
take well under a second and need no network. A new ``pyproject.toml``, other extras or a
venv made anew (no stamp in it) install again. ``scripts/install`` writes the same stamp.

The stamp is written only after an install succeeded and never removed before one: when
installing fails (no network), the last good install is still in ``.venv`` and its stamp
still names what it holds, so restoring ``pyproject.toml`` needs no install at all.

``python3 scripts/dotvenv.py EXTRA,EXTRA`` exits 0 when ``.venv`` holds those extras of
this ``pyproject.toml`` and 1 otherwise; with ``--before`` first, 0 when it holds them of
any ``pyproject.toml``, a last good install (``scripts/test`` asks both).
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VENV = ROOT / ".venv"
STAMP = "phantomtouch-install.stamp"
SERVICE_EXTRAS = ("server", "audio", "plot", "osc", "fleet")


class InstallFailed(Exception):
    """pip could not install; the message is one line saying so and what still works."""


def python_of(venv_dir: Path = VENV) -> Path:
    """The venv's interpreter (``Scripts\\python.exe`` on Windows, ``bin/python`` elsewhere)."""
    if sys.platform == "win32":
        return venv_dir / "Scripts" / "python.exe"
    return venv_dir / "bin" / "python"


def stamp_text(extras: tuple[str, ...], root: Path = ROOT) -> str:
    """What the stamp holds once ``extras`` are installed from ``root/pyproject.toml``."""
    digest = hashlib.sha256((root / "pyproject.toml").read_bytes()).hexdigest()
    return f"{digest} {','.join(sorted(extras))}\n"


def _stamped_extras(venv_dir: Path) -> tuple[str, set[str]] | None:
    """The stamp's digest and extras, or None without a venv or a stamp."""
    stamp = venv_dir / STAMP
    if not python_of(venv_dir).exists() or not stamp.exists():
        return None
    digest, _, have = stamp.read_text(encoding="utf-8").strip().partition(" ")
    return digest, set(have.split(","))


def installed(extras: tuple[str, ...], venv_dir: Path = VENV, root: Path = ROOT) -> bool:
    """Whether ``venv_dir`` holds ``extras`` (or more) of this ``pyproject.toml``."""
    stamped = _stamped_extras(venv_dir)
    if stamped is None:
        return False
    wanted = stamp_text(extras, root).split()[0]
    return stamped[0] == wanted and set(extras) <= stamped[1]


def installed_before(extras: tuple[str, ...], venv_dir: Path = VENV) -> bool:
    """Whether ``venv_dir`` holds ``extras`` of some ``pyproject.toml``, this one or an
    earlier one: a last good install to go on with when a new one cannot be made."""
    stamped = _stamped_extras(venv_dir)
    return stamped is not None and set(extras) <= stamped[1]


def _pip(python: Path, *args: str) -> None:
    """``pip install -q ARGS``; its error lines go to stderr, a failure raises."""
    done = subprocess.run(
        [str(python), "-m", "pip", "install", "-q", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        errors = [line for line in done.stdout.splitlines() if line.startswith("ERROR")]
        last = (errors or done.stdout.strip().splitlines() or ["(no output)"])[-1]
        raise InstallFailed(f"pip install failed (exit {done.returncode}): {last}")


def ensure(extras: tuple[str, ...], *, editable_client: bool = False) -> Path:
    """Install ``extras`` into ``.venv`` unless its stamp says they are there; its python.

    Raises
    ------
    InstallFailed
        pip failed; ``.venv`` and its stamp are as they were before the attempt.
    """
    python = python_of()
    if installed(extras):
        return python
    if not python.exists():
        venv.EnvBuilder(with_pip=True).create(VENV)
    print(f"installing phantomtouch[{','.join(extras)}] into {VENV} ...", file=sys.stderr)
    _pip(python, "-e", f"{ROOT}[{','.join(extras)}]")
    if editable_client:
        _pip(python, "-e", str(ROOT / "sdk_clients" / "python"))
    (VENV / STAMP).write_text(stamp_text(extras), encoding="utf-8")
    print(f"installed phantomtouch[{','.join(extras)}] into {VENV}", file=sys.stderr)
    return python


if __name__ == "__main__":
    check = installed_before if sys.argv[1] == "--before" else installed
    sys.exit(0 if check(tuple(sys.argv[-1].split(","))) else 1)
