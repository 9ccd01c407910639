"""The project's virtual environment, ``.venv``, installed once and again only when needed.

``python scripts/run.py`` and ``python scripts/test.py`` (Windows, macOS and Linux alike;
``scripts/run`` on Linux and macOS calls the first) make ``.venv`` with the extras they need
and write a stamp into it: the SHA-256 of ``pyproject.toml`` and the extras installed.
Later starts compare the stamp and install nothing when it matches, so they take well
under a second and need no network. A new ``pyproject.toml``, other extras or a venv made
anew (no stamp in it) install again. ``scripts/install`` writes the same stamp.
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


def python_of(venv_dir: Path = VENV) -> Path:
    """The venv's interpreter (``Scripts\\python.exe`` on Windows, ``bin/python`` elsewhere)."""
    if sys.platform == "win32":
        return venv_dir / "Scripts" / "python.exe"
    return venv_dir / "bin" / "python"


def stamp_text(extras: tuple[str, ...], root: Path = ROOT) -> str:
    """What the stamp holds once ``extras`` are installed from ``root/pyproject.toml``."""
    digest = hashlib.sha256((root / "pyproject.toml").read_bytes()).hexdigest()
    return f"{digest} {','.join(sorted(extras))}\n"


def installed(extras: tuple[str, ...], venv_dir: Path = VENV, root: Path = ROOT) -> bool:
    """Whether ``venv_dir`` holds ``extras`` (or more) of this ``pyproject.toml``."""
    stamp = venv_dir / STAMP
    if not python_of(venv_dir).exists() or not stamp.exists():
        return False
    digest, _, have = stamp.read_text(encoding="utf-8").strip().partition(" ")
    wanted = stamp_text(extras, root).split()[0]
    return digest == wanted and set(extras) <= set(have.split(","))


def ensure(extras: tuple[str, ...], *, editable_client: bool = False) -> Path:
    """Install ``extras`` into ``.venv`` unless its stamp says they are there; its python."""
    python = python_of()
    if installed(extras):
        return python
    if not python.exists():
        venv.EnvBuilder(with_pip=True).create(VENV)
    (VENV / STAMP).unlink(missing_ok=True)
    spec = f"{ROOT}[{','.join(extras)}]"
    subprocess.run([str(python), "-m", "pip", "install", "-q", "-e", spec], check=True)
    if editable_client:
        client = ROOT / "sdk_clients" / "python"
        subprocess.run([str(python), "-m", "pip", "install", "-q", "-e", str(client)], check=True)
    (VENV / STAMP).write_text(stamp_text(extras), encoding="utf-8")
    print(f"installed phantomtouch[{','.join(extras)}] into {VENV}", file=sys.stderr)
    return python
