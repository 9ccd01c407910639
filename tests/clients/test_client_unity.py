"""The Unity scripts (sdk_clients/unity), compiled with mcs and run against the service.

No Unity editor runs here. The scripts are compiled as C# 7.2 (the newest mcs takes)
against a stub of the UnityEngine members they use (tests/clients/unity_stub); the
transport core, which has no UnityEngine dependency, is compiled with a console harness
(tests/clients/unity_harness) and run with mono against the live service: REST routes, a
WebSocket stroke and a reconnect across a server restart, each checked from the server's
side, and the moves over the contact lane, counted by the service in ``/metrics``.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.clients.live import ROOT, LineProcess, Observer, get, require_tool
from tests.support.live_server import HOST, LiveServer
from tests.support.metrics import scrape

UNITY = ROOT / "sdk_clients" / "unity"
STUB = Path(__file__).parent / "unity_stub"
HARNESS = Path(__file__).parent / "unity_harness"
MCS_FLAGS = ["-langversion:7.2", "-warnaserror+", "-nologo"]


def sources(folder: Path) -> list[str]:
    return sorted(str(p) for p in folder.rglob("*.cs"))


def compile_cs(args: list[str]) -> None:
    mcs = require_tool("mcs")
    done = subprocess.run([mcs, *MCS_FLAGS, *args], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"mcs failed:\n{done.stdout}\n{done.stderr}"


@pytest.fixture(scope="module")
def harness(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """The console harness, built from the Unity client's core and run with mono."""
    mono = require_tool("mono")
    exe = tmp_path_factory.mktemp("unity-harness") / "harness.exe"
    core = sources(UNITY / "Runtime" / "Core")
    compile_cs(["-r:System.Net.Http.dll", f"-out:{exe}", *core, *sources(HARNESS)])
    return [mono, "--debug", str(exe)]


def run(harness: list[str], *args: str, timeout_s: float = 60) -> dict[str, str]:
    done = subprocess.run([*harness, *args], capture_output=True, text=True, timeout=timeout_s)
    assert done.returncode == 0, f"harness {args[0]} failed:\n{done.stdout}\n{done.stderr}"
    return parse(done.stdout)


def parse(stdout: str) -> dict[str, str]:
    lines = dict(line.partition(" ")[::2] for line in stdout.splitlines() if line)
    assert "DONE" in lines, stdout
    return lines


def test_unity_scripts_compile_against_the_unity_stub(tmp_path: Path) -> None:
    engine = tmp_path / "UnityEngine.dll"
    compile_cs(["-target:library", f"-out:{engine}", *sources(STUB)])
    scripts = tmp_path / "PhantomTouch.dll"
    compile_cs(["-target:library", f"-r:{engine}", f"-out:{scripts}", *sources(UNITY)])


def test_unity_core_json_and_forearm_mapping(harness: list[str]) -> None:
    out = run(harness, "selftest")
    # Run under a comma-decimal culture: numbers must still be written with a point.
    assert out["JSON"] == '{"type":"move","contact":"finger","x_cm":1.5,"y_cm":12.25}'
    assert out["MAP_WRIST"] == "1.9,0"  # centre of the band's width, wrist end
    assert out["MAP_ELBOW"] == "1.9,14.4"
    assert out["MAP_EDGE"] == "3.8,7.2"  # half the width off the axis: the band's edge
    assert out["MAP_BEYOND"] == "0,14.4"  # clamped onto the band
    assert '"intensity":1,' in out["TAP"]  # clamped to 0-1


def test_unity_client_rest_routes(harness: list[str], server: LiveServer) -> None:
    out = run(harness, "rest", server.url)
    assert out["HEALTH"] == "ok"
    job = get(server, f"/jobs/{out['JOB']}")
    assert job.status_code == 200, "the harness's touch is a job on the server"
    assert job.json()["state"] in {"scheduled", "playing", "finished", "stopped"}
    assert out["CANCELLED"] in {"stopped", "finished"}
    assert out["WAV"] == "RIFFWAVE"
    assert 0 < int(out["PLAN_POINTS"]) <= 500
    assert float(out["STORED"]) == 20.0
    assert float(out["STORED_JOB"]) == 20.0, "TouchRequest.Stored plays the stored pattern"
    assert out["DELETED"] == "not_found 404"
    assert out["REFUSED"].split()[0] == "invalid"
    assert int(out["METRICS_LINES"]) > 1


def test_unity_client_websocket_stroke(
    harness: list[str], server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    out = run(harness, "stroke", server.url, "unity-stroke")
    assert float(out["PING"]) > 0
    assert out["WS_REFUSED"] == "unknown_type"
    assert get(server, f"/jobs/{out['WS_JOB']}").status_code == 200
    positions = observer.positions("unity-stroke")
    assert positions, "the server never showed the harness's contact"
    assert positions[0] == pytest.approx((1.9, 2.0), abs=0.3)
    assert positions[-1] == pytest.approx((1.9, 12.0))
    ys = [y for _, y in positions]
    assert ys == sorted(ys) and len(set(ys)) >= 3, "the contact moved along the forearm"
    observer.wait_gone("unity-stroke", timeout_s=5)


def test_unity_client_reconnects_after_a_server_restart(
    harness: list[str],
    restartable_server: LiveServer,
    observe: Callable[[LiveServer], Observer],
) -> None:
    live = restartable_server
    child = LineProcess([*harness, "reconnect", live.url, "unity-survivor"])
    try:
        child.expect("WELCOME")
        child.expect("DOWN")
        live.stop()
        child.tell("stopped")
        child.expect("LOST")
        live.start()
        child.tell("started")
        assert int(child.expect("RECONNECTED")) >= 1
        observer = observe(live)
        # Put back down at the position it was moved to while the server was away.
        observer.wait_for("unity-survivor", lambda p: p == pytest.approx((1.9, 6.0)), timeout_s=5)
        child.tell("move")
        child.expect("MOVED")
        observer.wait_for("unity-survivor", lambda p: p == pytest.approx((1.9, 9.0)), timeout_s=5)
        child.tell("up")
        child.expect("UP")
        observer.wait_gone("unity-survivor", timeout_s=5)
        child.expect("DONE")
        assert child.finish() == 0, child.stderr()
    finally:
        child.close()


def moves_in(server: LiveServer) -> tuple[float, float, float]:
    """How many moves the service took so far: ``(over /ws, over the lane, refused by the
    lane)``."""
    counter = "phantomtouch_ws_messages_total"
    return (
        scrape(server.url, counter, direction="in", type="move"),
        scrape(server.url, counter, direction="in", type="lane_move"),
        scrape(server.url, counter, direction="in", type="lane_refused"),
    )


@pytest.mark.parametrize("lane", ["on", "off", "not offered"])
def test_unity_client_moves_over_the_contact_lane(
    harness: list[str],
    server: LiveServer,
    observe: Callable[[LiveServer], Observer],
    tmp_path: Path,
    lane: str,
) -> None:
    if lane == "not offered":
        env = {"PHANTOMTOUCH_CONTACT_LANE": "false"}
        with LiveServer(tmp_path / "p.db", env=env) as own:
            check_lane_run(harness, own, observe(own), lane)
    else:
        check_lane_run(harness, server, observe(server), lane)


def check_lane_run(harness: list[str], server: LiveServer, observer: Observer, lane: str) -> None:
    """Run the harness's ``lane`` command and check the server's side of it."""
    contact = f"unity-lane-{lane.replace(' ', '-')}"
    before = moves_in(server)
    out = run(harness, "lane", server.url, contact, "off" if lane == "off" else "on")
    positions = observer.positions(contact)
    assert positions and positions[-1] == pytest.approx((1.9, 12.0)), positions[-3:]
    assert out["REFUSED"].split()[0] == "invalid" and "y_cm" in out["REFUSED"], out["REFUSED"]
    assert float(out["PING"]) > 0, "the session goes on after the refusal"
    ws_moves, lane_moves, lane_refused = (
        a - b for a, b in zip(moves_in(server), before, strict=True)
    )
    if lane == "on":
        assert out["LANE"] == f"{HOST}:{int(out['OFFERED'])}"
        # the client sends a contact's newest move once a frame: a sender woken late on a
        # busy machine merges two moves of the 20 into one, and the newest still arrives
        sent = int(out["LANE_SENT"])
        assert 1 <= sent <= 20
        assert (ws_moves, lane_moves, lane_refused) == (0, sent, 1), "every move on the lane"
        assert out["CLOSED"] == "True", "the lane closes with the session"
    else:
        offered = out["OFFERED"] != "none"
        assert offered == (lane == "off"), "lane off: offered, not taken"
        assert out["LANE"] == "none"
        assert 1 <= ws_moves <= 20 and (lane_moves, lane_refused) == (0, 0), "moves over /ws"
