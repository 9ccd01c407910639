"""``phantomtouch bhaptics register``: the keys bHaptics' Windows libraries look for.

The registry is the file stand-in (:class:`FileUserRegistry`, the same interface as the
real one, on disk); what a library checks is done here as the references describe it
(docs/bhaptics.md, "Windows"): the default value of ``bhaptics-app\\shell\\open\\command``
below the user's ``Software\\Classes`` names a program (installed), and a process named
after that program's stem counts as the Player running. The program put there is a copy of
phantomtouch's own launcher, run here as a real subprocess.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path, PureWindowsPath

import pytest

from phantomtouch import __version__
from phantomtouch.bhaptics.user_registry import FileUserRegistry, user_registry
from phantomtouch.cli import main
from phantomtouch.commands.bhaptics import PLAYER_ARGV, player_argv
from phantomtouch.errors import DeviceError

LAUNCHER = Path(sys.executable).with_name("phantomtouch")
"""phantomtouch's own launcher in this checkout's environment (scripts/install)."""


def installed_program(registry_file: Path) -> str | None:
    """What a library reads: HKCR\\bhaptics-app\\shell\\open\\command's default value, of
    which the per-user part is HKCU\\Software\\Classes (keys in any case)."""
    keys = {k.lower(): v for k, v in json.loads(registry_file.read_text("utf-8")).items()}
    command = keys.get(r"software\classes\bhaptics-app\shell\open\command", {}).get("")
    if command is None:
        return None
    return shlex.split(command, posix=False)[0].strip('"')


def registered(tmp_path: Path) -> tuple[Path, Path]:
    registry, install = tmp_path / "user.json", tmp_path / "player"
    status = main(
        [
            "bhaptics",
            "register",
            "--registry",
            str(registry),
            "--install-dir",
            str(install),
            "--program",
            str(LAUNCHER),
        ]
    )
    assert status == 0
    return registry, install


def test_register_writes_what_the_libraries_look_for_and_the_program_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    registry, install = registered(tmp_path)
    assert "registered" in capsys.readouterr().out
    program = installed_program(registry)
    assert program is not None  # "installed"
    assert Path(program) == install / "BhapticsPlayer.exe"
    assert Path(program).read_bytes() == LAUNCHER.read_bytes()
    # "running" is a process named after the program: BhapticsPlayer
    assert PureWindowsPath(program).stem == "BhapticsPlayer"
    keys = json.loads(registry.read_text("utf-8"))
    assert keys[r"software\classes\bhaptics-app"] == {"": "URL:bhaptics-app", "URL Protocol": ""}
    assert keys[r"software\classes\bhaptics-app\shell\open\command"] == {"": f'"{program}" "%1"'}
    # the copy is phantomtouch: run under the Player's name it passes arguments through
    ran = subprocess.run([program, "--version"], capture_output=True, text=True, timeout=60)
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.strip() == f"phantomtouch {__version__}"


def test_started_as_the_player_it_serves_as_the_player() -> None:
    for argv0 in (r"C:\Users\a\phantomtouch\BhapticsPlayer.exe", "/x/bhapticsplayer.EXE"):
        assert player_argv(argv0, []) == list(PLAYER_ARGV)
        assert player_argv(argv0, ["bhaptics-app://open"]) == list(PLAYER_ARGV)
        assert player_argv(argv0, ["presets"]) == ["presets"]
    assert player_argv("/usr/bin/phantomtouch", []) is None
    assert PLAYER_ARGV == ("serve", "--bhaptics", "127.0.0.1:15881")


def test_remove_takes_it_away_and_again_finds_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    registry, install = registered(tmp_path)
    FileUserRegistry(registry).set(r"Software\Classes\bhaptics-app2", "", "someone else's")
    capsys.readouterr()
    args = ["bhaptics", "register", "--remove", "--registry", str(registry)]
    assert main([*args, "--install-dir", str(install)]) == 0
    assert "removed HKEY_CURRENT_USER" in capsys.readouterr().out
    assert installed_program(registry) is None
    assert not install.exists()
    keys = json.loads(registry.read_text("utf-8"))
    assert keys[r"software\classes\bhaptics-app2"] == {"": "someone else's"}
    ours = "software\\classes\\bhaptics-app"
    assert not [k for k in keys if k == ours or k.startswith(ours + "\\")]
    assert main([*args, "--install-dir", str(install)]) == 0
    assert capsys.readouterr().out.strip() == "nothing to remove"


def test_remove_leaves_another_programs_registration(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    registry = tmp_path / "user.json"
    real = r'"C:\Program Files\bHaptics\BhapticsPlayer.exe" "%1"'
    FileUserRegistry(registry).set(r"Software\Classes\bhaptics-app\shell\open\command", "", real)
    args = ["bhaptics", "register", "--remove", "--registry", str(registry)]
    assert main([*args, "--install-dir", str(tmp_path / "player")]) == 1
    assert "not this stand-in's" in capsys.readouterr().err
    assert installed_program(registry) == r"C:\Program Files\bHaptics\BhapticsPlayer.exe"


def test_the_file_registry_behaves_as_the_registry(tmp_path: Path) -> None:
    registry = FileUserRegistry(tmp_path / "sub" / "user.json")
    assert registry.get(r"Software\X") is None
    assert not registry.delete_tree(r"Software\X")
    registry.set(r"Software\X\Y\Z", "v", "1")
    assert registry.get(r"software\x\y\z", "v") == "1"  # keys in any case
    assert registry.get(r"Software\X\Y") is None  # the parent exists, without a value
    assert registry.get(r"Software\X\Y\Z") is None  # no default value written
    assert registry.delete_tree(r"SOFTWARE\X")
    assert json.loads((tmp_path / "sub" / "user.json").read_text("utf-8")) == {"software": {}}
    (tmp_path / "bad.json").write_text("[1, 2]", "utf-8")
    with pytest.raises(DeviceError, match="must map each key"):
        FileUserRegistry(tmp_path / "bad.json").get("Software")


@pytest.mark.skipif(sys.platform == "win32", reason="off Windows there is no registry")
def test_off_windows_the_real_registry_is_refused_naming_the_stand_in(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(DeviceError, match="give --registry FILE"):
        user_registry(None)
    assert main(["bhaptics", "register", "--remove"]) == 1
    assert "exists only on Windows" in capsys.readouterr().err
