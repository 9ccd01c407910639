"""The Godot clients: the Godot 4 addon (parsed and linted) and the wire protocol spoken
by a real Godot engine (Godot 3, headless) to the live service.

No Godot 4 engine is installed here, so the addon (sdk_clients/godot) is checked with
gdtoolkit's parser and linter only. The protocol itself is proven from a game engine with
``godot3-server``: tests/clients/godot3/touch_and_stroke.gd POSTs a touch and streams a
contact over the WebSocket (or its moves over the contact lane, with ``PacketPeerUDP``), and
the test checks on the server that both arrived and which way the moves went.
"""

from __future__ import annotations

import configparser
import os
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.clients.live import ROOT, Observer, get, require, require_tool
from tests.support.live_server import LiveServer
from tests.support.metrics import scrape

ADDON = ROOT / "sdk_clients" / "godot" / "addons" / "phantomtouch"
GODOT3_PROJECT = Path(__file__).parent / "godot3"
GODOT3_SCRIPT = "res://touch_and_stroke.gd"
MARKER = "PHANTOMTOUCH_GODOT3_OK"
BIN = Path(sys.executable).parent


def gdtool(name: str) -> str:
    path = BIN / name
    require(path.exists(), f"gdtoolkit's {name} (pip install gdtoolkit)")
    return str(path)


def addon_scripts() -> list[str]:
    scripts = sorted(str(p) for p in ADDON.glob("*.gd"))
    assert scripts
    return scripts


def test_godot4_addon_parses() -> None:
    done = subprocess.run(
        [gdtool("gdparse"), *addon_scripts()], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_godot4_addon_is_lint_clean_and_formatted() -> None:
    lint = subprocess.run(
        [gdtool("gdlint"), *addon_scripts()], capture_output=True, text=True, timeout=60
    )
    assert lint.returncode == 0, lint.stdout + lint.stderr
    form = subprocess.run(
        [gdtool("gdformat"), "--check", *addon_scripts()],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert form.returncode == 0, form.stdout + form.stderr


def test_godot4_plugin_cfg_names_the_plugin_and_its_autoload() -> None:
    cfg = configparser.ConfigParser()
    cfg.read(ADDON / "plugin.cfg")
    plugin = {k: v.strip('"') for k, v in cfg["plugin"].items()}
    assert {"name", "description", "author", "version", "script"} <= plugin.keys()
    plugin_script = (ADDON / plugin["script"]).read_text()
    assert plugin_script.startswith("@tool\nextends EditorPlugin")
    autoload = re.search(r'AUTOLOAD_PATH := "res://addons/phantomtouch/(\w+\.gd)"', plugin_script)
    assert autoload is not None and (ADDON / autoload.group(1)).exists()
    name = re.search(r'AUTOLOAD_NAME := "(\w+)"', plugin_script)
    assert name is not None
    zone = (ADDON / "forearm_touch_zone.gd").read_text()
    assert "extends Area3D" in zone
    assert f'client_path: NodePath = ^"/root/{name.group(1)}"' in zone


def godot3(tmp_path: Path, *args: str, env: dict[str, str] | None = None) -> str:
    binary = require_tool("godot3-server")
    home = tmp_path / "home"
    home.mkdir(exist_ok=True)
    done = subprocess.run(
        ["timeout", "30", binary, "--path", str(GODOT3_PROJECT), "-s", GODOT3_SCRIPT, *args],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "HOME": str(home), **(env or {})},
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    return output


def test_godot3_script_parses(tmp_path: Path) -> None:
    # Godot 3 exits 0 even when a script does not parse; --check-only does not.
    output = godot3(tmp_path, "--check-only")
    assert "SCRIPT ERROR" not in output and "Parse Error" not in output, output


def moves_in(server: LiveServer) -> tuple[float, float]:
    """How many moves the service took so far: ``(over /ws, over the lane)``."""
    counter = "phantomtouch_ws_messages_total"
    return (
        scrape(server.url, counter, direction="in", type="move"),
        scrape(server.url, counter, direction="in", type="lane_move"),
    )


@pytest.mark.parametrize("lane", ["off", "on"])
def test_godot3_engine_posts_a_touch_and_streams_a_contact(
    tmp_path: Path, server: LiveServer, observe: Callable[[LiveServer], Observer], lane: str
) -> None:
    observer = observe(server)
    before = moves_in(server)
    output = godot3(tmp_path, env={"PHANTOMTOUCH_URL": server.url, "PHANTOMTOUCH_LANE": lane})
    assert MARKER in output.splitlines(), output
    job_id = re.search(r"^JOB (\S+)$", output, re.MULTILINE)
    assert job_id is not None, output
    job = get(server, f"/jobs/{job_id.group(1)}")
    assert job.status_code == 200, "Godot's touch is a job on the server"
    positions = observer.positions("godot3-stroke")
    assert positions, "the server never showed Godot's contact"
    assert positions[-1] == pytest.approx((1.9, 12.0))
    ys = [y for _, y in positions]
    assert ys == sorted(ys) and len(set(ys)) >= 3, "the contact moved along the forearm"
    observer.wait_gone("godot3-stroke", timeout_s=5)
    ws_moves, lane_moves = (a - b for a, b in zip(moves_in(server), before, strict=True))
    if lane == "on":
        assert re.search(r"^LANE \d+$", output, re.MULTILINE), output
        assert "LANE_REFUSED y_cm" in output.splitlines(), output
        assert (ws_moves, lane_moves) == (0, 60), "every move over the lane"
    else:
        assert (ws_moves, lane_moves) == (60, 0)
