"""``phantomtouch bhaptics register [--remove]``: make the bHaptics Player look installed.

bHaptics' Windows libraries (``bhaptics_library.dll`` of the SDK2 Unity and Unreal plugins,
the C++ SDK) refuse to connect unless the Player looks installed and running. What they
look at (docs/bhaptics.md, "Windows"):

- installed: the default value of ``HKEY_CLASSES_ROOT\\bhaptics-app\\shell\\open\\command``,
  the Player's ``bhaptics-app:`` URL handler, names the Player's program;
- running: a process whose name is that program's (``BhapticsPlayer``); when there is
  none, some start that program, without arguments.

``register`` writes, for the current user only (``HKEY_CURRENT_USER\\Software\\Classes``,
which Windows merges into ``HKEY_CLASSES_ROOT``; no administrator), the ``bhaptics-app``
class whose command is ``"<install dir>\\BhapticsPlayer.exe" "%1"``, and puts there a copy
of phantomtouch's own launcher (``phantomtouch.exe``). Started under that name, phantomtouch
runs ``serve --bhaptics 127.0.0.1:15881`` (:func:`player_argv`): a game that launches "the
Player" starts the stand-in, and while it serves the process the libraries look for is
there. ``--remove`` deletes the class (only if it is this stand-in's) and the copy. A real
Player installed machine-wide is shadowed for this user until then.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path, PureWindowsPath

from phantomtouch.bhaptics.user_registry import UserRegistry, user_registry
from phantomtouch.errors import DeviceError

CLASS_KEY = r"Software\Classes\bhaptics-app"
"""The Player's URL class, below ``HKEY_CURRENT_USER``."""
COMMAND_KEY = CLASS_KEY + r"\shell\open\command"
"""Its default value is the Player's command line: the program the libraries look for."""
PLAYER_EXE = "BhapticsPlayer.exe"
"""The program's name: the process name the libraries look for is its stem."""
PLAYER_ARGV = ("serve", "--bhaptics", "127.0.0.1:15881")
"""What phantomtouch runs when started as :data:`PLAYER_EXE` without arguments."""


def player_argv(argv0: str, args: Sequence[str]) -> list[str] | None:
    """The arguments phantomtouch runs with when started as ``argv0`` with ``args``.

    Started as :data:`PLAYER_EXE` (any case, any folder) with no argument or with only a
    ``bhaptics-app:`` URL (the URL handler's ``"%1"``): :data:`PLAYER_ARGV`; with other
    arguments: those. Under any other name: None (the command line as given). Pure.
    """
    if PureWindowsPath(argv0).stem.lower() != PureWindowsPath(PLAYER_EXE).stem.lower():
        return None
    if not args or (len(args) == 1 and args[0].lower().startswith("bhaptics-app:")):
        return list(PLAYER_ARGV)
    return list(args)


def default_install_dir() -> Path:
    """``bhaptics-player`` in the service's data folder (beside its pattern library)."""
    from phantomtouch.service.settings import default_db_path

    return default_db_path().parent / "bhaptics-player"


def own_launcher() -> Path:
    """phantomtouch's launcher: ``phantomtouch.exe`` (Windows) or the ``phantomtouch``
    script beside the running Python.

    Raises
    ------
    DeviceError
        There is none (phantomtouch run as ``python -m phantomtouch`` from a checkout that
        was not installed): the message says to give ``--program``.
    """
    started = Path(sys.argv[0])
    if started.suffix.lower() == ".exe" and started.is_file():
        return started
    name = "phantomtouch.exe" if sys.platform == "win32" else "phantomtouch"
    beside = Path(sys.executable).with_name(name)
    if beside.is_file():
        return beside
    raise DeviceError(f"no {name} beside {sys.executable}; give --program PATH to copy")


def register(registry: UserRegistry, install_dir: Path, program: Path) -> Path:
    """Copy ``program`` to ``install_dir / PLAYER_EXE`` and point the ``bhaptics-app`` class
    of ``registry`` at it; returns the copy's path. Runs in the caller's thread.

    Raises
    ------
    DeviceError
        ``program`` cannot be copied, or the registry refused a write.
    """
    target = install_dir / PLAYER_EXE
    try:
        install_dir.mkdir(parents=True, exist_ok=True)
        if program.resolve() != target.resolve():
            shutil.copy2(program, target)
    except OSError as exc:
        raise DeviceError(f"cannot copy {str(program)!r} to {str(target)!r}: {exc}") from exc
    registry.set(CLASS_KEY, "", "URL:bhaptics-app")
    registry.set(CLASS_KEY, "URL Protocol", "")
    registry.set(COMMAND_KEY, "", f'"{target}" "%1"')
    return target


def unregister(registry: UserRegistry, install_dir: Path) -> list[str]:
    """Remove what :func:`register` wrote: the class (if its command is this stand-in's)
    and the program's copy; returns what was removed (empty: nothing was there).

    Raises
    ------
    DeviceError
        The class's command names another program (left as it is), or a removal failed.
    """
    target = install_dir / PLAYER_EXE
    removed = []
    command = registry.get(COMMAND_KEY)
    if command is not None and command != f'"{target}" "%1"':
        raise DeviceError(
            f"HKEY_CURRENT_USER\\{COMMAND_KEY} is {command!r}, not this stand-in's "
            f"({str(target)!r}): left as it is"
        )
    if registry.delete_tree(CLASS_KEY):
        removed.append(f"HKEY_CURRENT_USER\\{CLASS_KEY}")
    try:
        if target.exists():
            target.unlink()
            removed.append(str(target))
        if install_dir.is_dir() and not any(install_dir.iterdir()):
            install_dir.rmdir()
    except OSError as exc:
        raise DeviceError(f"cannot remove {str(target)!r}: {exc}") from exc
    return removed


def _run(args: argparse.Namespace) -> int:
    registry = user_registry(Path(args.registry) if args.registry else None)
    install_dir = Path(args.install_dir) if args.install_dir else default_install_dir()
    where = f" (in {args.registry})" if args.registry else ""
    if args.remove:
        removed = unregister(registry, install_dir)
        print(f"removed {', '.join(removed)}{where}" if removed else "nothing to remove")
        return 0
    program = Path(args.program) if args.program else own_launcher()
    target = register(registry, install_dir, program)
    print(
        f"registered {target} as the bHaptics Player for this user "
        f"(HKEY_CURRENT_USER\\{COMMAND_KEY}){where}; a game that starts the Player starts "
        f"phantomtouch {' '.join(PLAYER_ARGV)}; phantomtouch bhaptics register --remove "
        "undoes it"
    )
    return 0


def add_bhaptics_command(sub: argparse._SubParsersAction) -> None:
    """Register ``phantomtouch bhaptics register``."""
    bhaptics = sub.add_parser("bhaptics", help="the bHaptics Player stand-in's setup")
    commands = bhaptics.add_subparsers(dest="bhaptics", required=True)
    command = commands.add_parser(
        "register",
        help="make bHaptics' Windows libraries see the Player installed (per user)",
    )
    command.add_argument("--remove", action="store_true", help="take the registration away again")
    command.add_argument(
        "--install-dir",
        help="where the Player's program is put (default: the service's data folder)",
    )
    command.add_argument(
        "--program", help="the program to put there (default: phantomtouch's own launcher)"
    )
    command.add_argument(
        "--registry",
        help="write the keys to this JSON file instead of the Windows registry (to inspect "
        "them, or on another system)",
    )
    command.set_defaults(func=_run)
