"""The Python client (sdk_clients/python) against the real service.

Every REST route and WebSocket message goes to a ``phantomtouch serve`` subprocess; what
the server did is checked from the server's side (job state, a second client's ``state``
stream). Two tests need no server: local validation, and the per-frame coalescing of
moves, which is measured on a recording WebSocket server in the test.
"""

from __future__ import annotations

import asyncio
import csv
import inspect
import io
import json
import re
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import soundfile
from phantomtouch_client import (
    AsyncClient,
    AsyncSession,
    Busy,
    Client,
    ClipSummary,
    Clock,
    DeviceInfo,
    Health,
    InvalidRequest,
    Job,
    JobStatus,
    MalformedMessage,
    NotFound,
    ParameterError,
    PlanSummary,
    RenderCurves,
    RenderPlan,
    Session,
    SessionState,
    StopAnswer,
    Summary,
    TouchPattern,
    Unauthorized,
    Wearer,
    WearerSummary,
    _calls,
)
from pydantic import BaseModel
from websockets.asyncio.server import ServerConnection, serve

import phantomtouch as service
from tests.clients.live import ROOT, Observer, get, running, wait_until
from tests.support.live_server import LiveServer

STROKE = TouchPattern.model_validate(
    {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 20.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
    }
)
JOB_STATES = {"scheduled", "playing", "finished", "stopped"}


@pytest.fixture
def client(server: LiveServer) -> Iterator[Client]:
    with Client(server.url) as pt:
        yield pt


def test_health_clock_device_presets(client: Client) -> None:
    assert client.health().status == "ok"
    first = client.clock()
    second = client.clock()
    assert second.server_time_s >= first.server_time_s
    assert first.sample_rate_hz > 0
    device = client.device()
    assert device.model_dump(exclude_none=True)
    names = {p.name for p in client.presets()}
    assert "exp2/curved" in names


def test_touch_with_preset_then_job_and_cancel(client: Client) -> None:
    job = client.touch(preset="exp2/curved", start_in_ms=50)
    assert job.duration_s > 0
    status = client.job(job.job_id)
    assert status.job_id == job.job_id
    assert status.state in JOB_STATES
    cancelled = client.cancel_job(job.job_id)
    assert cancelled.state in {"stopped", "finished"}


def test_touch_with_pattern_at_a_server_time(client: Client) -> None:
    start_at_s = client.clock().server_time_s + 0.2
    job = client.touch(STROKE, start_at_s=start_at_s)
    assert job.start_at_s == pytest.approx(start_at_s, abs=0.05)
    # Path 9.6 cm at 20 cm/s plus the fades (eq. 1).
    assert job.duration_s == pytest.approx(0.05 + 9.6 / 20.0 + 0.05, rel=1e-3)
    assert job.path_length_cm == pytest.approx(9.6, rel=1e-6)


def test_render_answers_an_eight_channel_float_wav(client: Client) -> None:
    wav = client.render(STROKE)
    samples, rate_hz = soundfile.read(io.BytesIO(wav), dtype="float32", always_2d=True)
    assert samples.shape[1] == 8
    assert samples.shape[0] == pytest.approx(0.58 * rate_hz, abs=2)
    assert soundfile.info(io.BytesIO(wav)).subtype == "FLOAT"
    assert np.isfinite(samples).all()


def test_render_plan_answers_curves(client: Client) -> None:
    plan = client.render_plan(preset="exp2/curved")
    curves = plan.curves
    assert 0 < len(curves.times_s) <= 500
    assert len(curves.positions_cm) == len(curves.times_s) == len(curves.gains)
    assert all(len(g) == 8 for g in curves.gains)


def test_patterns_put_list_get_play_delete(client: Client) -> None:
    name = "client-test.stroke"
    client.put_pattern(name, STROKE)
    assert name in {p.name for p in client.patterns()}
    assert client.get_pattern(name) == STROKE
    job = client.play_pattern(name, start_in_ms=10)
    assert client.job(job.job_id).state in JOB_STATES
    assert isinstance(client.touch(stored=name), Job)
    client.delete_pattern(name)
    with pytest.raises(NotFound):
        client.get_pattern(name)


def test_clips_put_list_get_play_delete(client: Client) -> None:
    clip = {
        "duration_s": 0.5,
        "amplitude": [{"t_s": 0.0, "value": 0.2}, {"t_s": 0.5, "value": 1.0}],
        "transients": [{"t_s": 0.1, "amplitude": 0.8, "frequency": 0.5}],
    }
    summary = client.put_clip("client-test.clip", clip)
    assert (summary.duration_s, summary.amplitude_points, summary.transients) == (0.5, 2, 1)
    assert "client-test.clip" in {c.name for c in client.clips()}
    assert client.get_clip("client-test.clip").transients[0].amplitude == 0.8
    stroke = TouchPattern.model_validate(
        {
            **STROKE.model_dump(exclude_unset=True),
            "carrier": {"kind": "clip", "clip": "client-test.clip"},
        }
    )
    assert isinstance(client.touch(stroke), Job)
    client.delete_clip("client-test.clip")
    with pytest.raises(InvalidRequest) as refused:  # a body naming a missing thing: 422
        client.touch(stroke)
    assert refused.value.fields[0]["field"] == "carrier.clip"


def test_wearers_put_list_get_delete(client: Client) -> None:
    offsets = {"sine_100hz": {2: 2.5, 5: -1.5}, "noise_40_500hz": {"2": 1.0}}
    stored = client.put_wearer("client-test.wearer", offsets, note="left forearm")
    assert stored.offsets_db == {"sine_100hz": {"2": 2.5, "5": -1.5}, "noise_40_500hz": {"2": 1.0}}
    listed = {w.name: w for w in client.wearers()}
    assert listed["client-test.wearer"].active is False
    assert client.get_wearer("client-test.wearer").note == "left forearm"
    with pytest.raises(InvalidRequest) as refused:
        client.put_wearer("client-test.bad", {"sine_100hz": {3: 25.0}})
    assert refused.value.fields[0]["field"] == "offsets_db.sine_100hz.3"
    client.delete_wearer("client-test.wearer")
    with pytest.raises(NotFound):
        client.get_wearer("client-test.wearer")


def test_the_client_chooses_the_wearer_while_the_service_runs(server: LiveServer) -> None:
    with Client(server.url) as pt:
        pt.put_wearer("client-test.chosen", {"sine_100hz": {2: 6.0, 8: -3.0}})
        chosen = pt.use_wearer("client-test.chosen", band="sine_100hz")
        assert (chosen.name, chosen.band) == ("client-test.chosen", "sine_100hz")
        assert chosen.offsets_db == pytest.approx([0.0, 6.0, 0, 0, 0, 0, 0, -3.0], abs=1e-5)
        assert pt.health().wearer == "client-test.chosen"
        with pytest.raises(InvalidRequest) as refused:
            pt.use_wearer("client-test.nobody")
        assert refused.value.fields[0]["field"] == "name"
        assert pt.wearer().name == "client-test.chosen"

    async def off() -> None:
        async with AsyncClient(server.url) as pt:
            assert (await pt.use_wearer("client-test.chosen")).name == "client-test.chosen"
            await pt.no_wearer()
            assert (await pt.wearer()).name is None
            assert (await pt.health()).wearer is None

    asyncio.run(off())
    with Client(server.url) as pt:
        assert pt.wearer().offsets_db == [0.0] * 8
        with pt.session(wearer="client-test.chosen") as ws:
            assert ws.welcome is not None
            assert ws.welcome.wearer == {"name": "client-test.chosen", "band": "sine_100hz"}
        assert pt.wearer().name == "client-test.chosen", "it stays when the session closes"
        pt.no_wearer()
        pt.delete_wearer("client-test.chosen")


def test_stop_and_metrics(client: Client) -> None:
    job = client.touch(preset="exp2/curved")
    client.stop()
    wait_until(
        lambda: client.job(job.job_id).state in {"stopped", "finished"},
        timeout_s=5,
        what="the job to stop",
    )
    text = client.metrics()
    assert "# TYPE" in text


def test_refusals_raise_the_exception_of_their_code(client: Client) -> None:
    with pytest.raises(InvalidRequest) as refused:
        client.touch(preset="exp2/curved", overrides={"speed_cm_s": -1})
    assert refused.value.status in (400, 422)
    assert "speed_cm_s" in str(refused.value)
    with pytest.raises(NotFound):
        client.touch(preset="no/such-preset")
    with pytest.raises(NotFound):
        client.job("no-such-job")


def test_a_bad_pattern_is_refused_before_it_is_sent() -> None:
    # Nothing listens on this address: the error must come from local validation.
    with Client("http://127.0.0.1:9") as pt:
        with pytest.raises(InvalidRequest) as refused:
            pt.touch({"path": {"kind": "polyline", "points_cm": [[0, 0]]}, "speed_cm_s": 0})
        assert refused.value.fields[0]["field"] == "speed_cm_s"
        with pytest.raises(ParameterError):
            pt.touch(STROKE, preset="exp2/curved")


def test_async_client(server: LiveServer) -> None:
    async def main() -> None:
        async with AsyncClient(server.url) as pt:
            assert (await pt.health()).status == "ok"
            job = await pt.touch(STROKE, start_in_ms=10)
            assert (await pt.job(job.job_id)).state in JOB_STATES
            assert "exp2/curved" in {p.name for p in await pt.presets()}

    asyncio.run(main())


def test_session_welcome_ping_play_stop(server: LiveServer) -> None:
    with Client(server.url) as pt, pt.session(client_name="pytest") as ws:
        assert ws.welcome is not None
        assert ws.welcome.protocol == 1
        assert ws.welcome.watchdog_s > 0
        before = pt.clock().server_time_s
        began = time.monotonic()
        assert ws.ping() >= before
        ping_s = time.monotonic() - began
        assert ws.rtt_s is not None and 0.0 < ws.rtt_s <= ping_s, "the round trip of the ping"
        job = ws.play(preset="exp2/curved", start_in_ms=20)
        assert pt.job(job.job_id).state in JOB_STATES
        ws.stop(job.job_id)
        wait_until(
            lambda: pt.job(job.job_id).state in {"stopped", "finished"},
            timeout_s=5,
            what="the job to stop",
        )


def test_session_errors_raise(server: LiveServer) -> None:
    with Session(server.ws_url) as ws:
        with pytest.raises(InvalidRequest):
            ws.down("finger", 1.9, 2.0, intensity=7.0)
        with pytest.raises(MalformedMessage):
            ws.request({"type": "no-such-type"})
        assert ws.ping() > 0  # the session survives both


def test_contact_stroke_arrives_and_moves(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    with Session(server.ws_url, client_name="stroker") as ws:
        finger = ws.contact("py-stroke")
        finger.down(1.9, 2.0, intensity=0.5)
        observer.wait_for("py-stroke", lambda p: p[1] == pytest.approx(2.0), timeout_s=5)
        for i in range(1, 41):
            finger.move(1.9, 2.0 + i * 0.25)
            time.sleep(1 / 90)
        observer.wait_for("py-stroke", lambda p: p[1] == pytest.approx(12.0), timeout_s=5)
        ys = [y for _, y in observer.positions("py-stroke")]
        assert ys == sorted(ys), "the contact only moves towards the elbow"
        assert len(set(ys)) >= 3, "the server saw the contact move, not jump"
        finger.up()
        observer.wait_gone("py-stroke", timeout_s=5)


def test_ping_loop_keeps_an_idle_contact(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    released: list[Any] = []
    with Session(server.ws_url, on_released=released.append) as ws:
        assert ws.welcome is not None
        ws.down("idle-finger", 1.0, 5.0)
        time.sleep(ws.welcome.watchdog_s * 1.5)
        assert released == []
        observer.wait_for("idle-finger", lambda p: True, timeout_s=2)
        ws.up("idle-finger")


def test_without_pings_the_watchdog_releases(server: LiveServer) -> None:
    released: list[Any] = []
    with Session(server.ws_url, ping_interval_s=60.0, on_released=released.append) as ws:
        assert ws.welcome is not None
        finger = ws.contact("silent-finger")
        finger.down(1.0, 5.0)
        wait_until(lambda: released, timeout_s=ws.welcome.watchdog_s * 3, what="released")
        assert released[0].contacts == ["silent-finger"]
        assert not finger.active


def test_a_global_stop_releases_every_sessions_contacts(server: LiveServer) -> None:
    released: list[Any] = []
    with Session(server.ws_url, on_released=released.append) as ws, Client(server.url) as pt:
        finger = ws.contact("stopped-finger")
        finger.down(1.0, 1.0)
        pt.stop()
        wait_until(lambda: released, timeout_s=5, what="released")
        assert released[0].reason == "stop"
        assert released[0].contacts == ["stopped-finger"]
        assert not finger.active
        finger.up()  # nothing is down: nothing is sent, nothing refused
        assert ws.active_contacts == {}
        assert ws.ping() > 0


def test_async_session_stroke(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)

    async def main() -> None:
        async with AsyncClient(server.url) as pt, pt.session() as ws:
            finger = ws.contact("async-stroke")
            await finger.down(3.8, 0.0)
            for i in range(1, 21):
                finger.move(3.8, i * 0.5)
                await asyncio.sleep(1 / 90)
            await asyncio.sleep(0.05)
            await finger.up()

    asyncio.run(main())
    observer.wait_for("async-stroke", lambda p: p[1] == pytest.approx(10.0), timeout_s=5)


def test_reconnect_after_the_server_restarts(
    restartable_server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    live = restartable_server
    connection: list[bool] = []
    with Client(live.url) as pt, pt.session(on_connection=connection.append) as ws:
        finger = ws.contact("survivor")
        finger.down(1.9, 3.0)
        live.stop()
        wait_until(lambda: ws.state is SessionState.RECONNECTING, timeout_s=5, what="loss")
        finger.move(1.9, 9.0)  # made while the server is down: restored on return
        live.start()
        wait_until(lambda: ws.connected, timeout_s=15, what="the reconnection")
        assert ws.reconnects >= 1
        assert connection[:3] == [True, False, True]
        observer = observe(live)
        observer.wait_for("survivor", lambda p: p == pytest.approx((1.9, 9.0)), timeout_s=5)
        job = ws.play(preset="exp2/curved")
        assert pt.job(job.job_id).state in JOB_STATES
        finger.up()
        observer.wait_gone("survivor", timeout_s=5)


class _Recorder:
    """A WebSocket server that speaks just enough protocol and records what it receives."""

    def __init__(self) -> None:
        self.received: list[dict[str, Any]] = []

    async def handler(self, ws: ServerConnection) -> None:
        async for frame in ws:
            message = json.loads(frame)
            self.received.append(message)
            kind = message["type"]
            if kind == "hello":
                welcome = {"type": "welcome", "protocol": 1, "server_time_s": 0.0}
                await ws.send(json.dumps({**welcome, "watchdog_s": 2.0, "device": {}}))
            elif kind == "ping":
                await ws.send(json.dumps({"type": "pong", "id": message["id"], "server_time_s": 1}))
            elif "id" in message:
                await ws.send(json.dumps({"type": "ok", "id": message["id"]}))


def test_contact_sends_at_most_one_move_per_frame_the_newest() -> None:
    recorder = _Recorder()
    frame_hz = 50.0

    async def main() -> float:
        async with serve(recorder.handler, "127.0.0.1", 0) as server:
            port = server.sockets[0].getsockname()[1]
            async with AsyncSession(f"ws://127.0.0.1:{port}/ws", move_rate_hz=frame_hz) as ws:
                finger = ws.contact("burst")
                await finger.down(0.0, 0.0)
                started = time.monotonic()
                for i in range(1, 501):  # 500 updates in about 0.25 s: a bursty tracker
                    finger.move(0.0, i * 0.01)
                    if i % 10 == 0:
                        await asyncio.sleep(0.005)
                await asyncio.sleep(2 / frame_hz)
                elapsed_s = time.monotonic() - started
                await finger.up()
        return elapsed_s

    elapsed_s = asyncio.run(main())
    moves = [m for m in recorder.received if m["type"] == "move"]
    # One move per frame at most (+1: the frame in progress when the burst began).
    assert 1 <= len(moves) <= elapsed_s * frame_hz + 1
    assert moves[-1]["y_cm"] == pytest.approx(5.0), "the newest position is the one sent"
    ys = [m["y_cm"] for m in moves]
    assert ys == sorted(ys)
    assert [m["type"] for m in recorder.received][-1] == "up"


EXAMPLES = ROOT / "sdk_clients" / "python" / "examples"


def test_example_trial_block_schedules_trials_back_to_back(
    server: LiveServer, tmp_path: Path
) -> None:
    log = tmp_path / "block.csv"
    command = [sys.executable, str(EXAMPLES / "trial_block.py"), "--url", server.url]
    command += ["--presets", "vr/tap", "vr/stroke", "--gap-s", "0.1", "--log", str(log)]
    subprocess.run(command, check=True, timeout=60)
    rows = list(csv.DictReader(log.open()))
    assert sorted(r["preset"] for r in rows) == ["vr/stroke", "vr/tap"]
    first, second = rows
    gap_s = float(second["start_at_s"]) - float(first["start_at_s"]) - float(first["duration_s"])
    assert gap_s == pytest.approx(0.1, abs=1e-3)
    for row in rows:
        assert get(server, f"/jobs/{row['job_id']}").status_code == 200


def test_example_live_stroke_moves_a_contact(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    command = [sys.executable, str(EXAMPLES / "live_stroke.py"), "--url", server.url]
    command += ["--from", "1.9", "12", "--to", "1.9", "2.4", "--speed-cm-s", "20"]
    subprocess.run(command, check=True, timeout=60)
    ys = [y for _, y in observer.positions("finger")]
    assert ys and ys == sorted(ys, reverse=True) and len(set(ys)) >= 3
    # The observer samples at 60 Hz a contact moving at 20 cm/s: within 1 cm of each end.
    assert ys[0] == pytest.approx(12.0, abs=1.0)
    assert ys[-1] == pytest.approx(2.4, abs=1.0)


def test_the_token_is_sent_and_a_missing_one_refused(tmp_path: Path) -> None:
    token = "client-test-token-0123"
    with running(tmp_path, args=("--token", token)) as live:
        with Client(live.url, token=token) as pt:
            assert pt.touch(preset="vr/tap").duration_s > 0
        with Client(live.url) as pt, pytest.raises(Unauthorized):
            pt.touch(preset="vr/tap")
        with Session(live.ws_url, token=token) as ws:
            ws.down("token-finger", 1.0, 1.0)
            ws.up("token-finger")
        with pytest.raises(Unauthorized), Session(live.ws_url, token="wrong-token-0123456789"):
            pass


# The client's answer models and the service's schemas of the same answers.
ANSWERS: dict[str, type[BaseModel]] = {
    "JobAccepted": Job,
    "JobInfo": JobStatus,
    "StopAnswer": StopAnswer,
    "PatternInfo": Summary,
    "PresetInfo": Summary,
    "ClipInfo": ClipSummary,
    "PlanSummary": PlanSummary,
    "RenderPlan": RenderPlan,
    "Curves": RenderCurves,
    "ClockInfo": Clock,
    "Health": Health,
    "DeviceInfo": DeviceInfo,
    "WearerProfile": Wearer,
    "WearerInfo": WearerSummary,
}


def test_answer_models_have_the_fields_of_the_openapi_document(server: LiveServer) -> None:
    schemas = get(server, "/openapi.json").json()["components"]["schemas"]
    for name, model in ANSWERS.items():
        schema = schemas[name]
        assert set(model.model_fields) == set(schema["properties"]), name
        required = {n for n, field in model.model_fields.items() if field.is_required()}
        assert required <= set(schema.get("required", [])), name


def test_the_client_calls_every_route_of_the_openapi_document(server: LiveServer) -> None:
    arguments = {
        "body": {"preset": "vr/tap"},
        "job_id": "J",
        "name": "N",
        "pattern": STROKE,
        "clip": {"duration_s": 1.0, "amplitude": [{"t_s": 0.0, "value": 1.0}]},
        "offsets_db": {},
    }
    calls = []
    for _, build in inspect.getmembers(_calls, inspect.isfunction):
        if str(build.__annotations__.get("return", "")).startswith("Call["):
            names = inspect.signature(build).parameters
            calls.append(build(**{n: arguments[n] for n in names if n in arguments}))
    routes = {
        (method.upper(), re.sub(r"\{[^}]+\}", "[^/]+", path) + "$")
        for path, operations in get(server, "/openapi.json").json()["paths"].items()
        for method in operations
    }
    called = {(m, p) for m, p in routes for c in calls if c.method == m and re.match(p, c.path)}
    assert called == routes, f"routes the client does not call: {routes - called}"
    # A call that is no route of the service is one of a fleet gateway (docs/fleet.md).
    routes |= _gateway_routes()
    for call in calls:
        assert any(call.method == m and re.match(p, call.path) for m, p in routes), call


def _gateway_routes() -> set[tuple[str, str]]:
    from phantomtouch.fleet.gateway import create_gateway
    from phantomtouch.fleet.gateway_settings import GatewaySettings
    from phantomtouch.fleet.settings import FleetSettings

    document = create_gateway(GatewaySettings(), FleetSettings()).openapi()
    return {
        (method.upper(), re.sub(r"\{[^}]+\}", "[^/]+", path) + "$")
        for path, operations in document["paths"].items()
        for method in operations
    }


# --- the client stands alone ---------------------------------------------------------------


def _components(schema: dict[str, Any]) -> dict[str, Any]:
    """A model's JSON Schema as named components, as /openapi.json holds them."""
    defs = dict(schema.pop("$defs", {}))
    defs[schema["title"]] = schema
    return defs


_WORDING = {"title", "description", "examples", "discriminator"}


def _rules(schema: Any) -> Any:
    """A schema without its wording; a union as the set of its branches (oneOf = anyOf
    for the disjoint, discriminated unions of the models)."""
    if isinstance(schema, list):
        return [_rules(item) for item in schema]
    if not isinstance(schema, dict):
        return schema
    rules = {key: _rules(value) for key, value in schema.items() if key not in _WORDING}
    if rules.get("default", 0) is None:
        del rules["default"]  # the document leaves out null defaults: absent is null
    branches = rules.pop("oneOf", None) or rules.pop("anyOf", None)
    if branches is not None:
        rules["anyOf"] = sorted(json.dumps(branch, sort_keys=True) for branch in branches)
    return rules


def test_the_clients_pattern_model_is_the_openapi_documents(server: LiveServer) -> None:
    # The client keeps its own copy of the service's TouchPattern (so that it needs
    # neither the service nor numpy): every component it uses, field by field (types,
    # bounds, defaults, required fields, cross-field rules), is the live document's.
    served = get(server, "/openapi.json").json()["components"]["schemas"]
    ours = _components(TouchPattern.model_json_schema(ref_template="#/components/schemas/{model}"))
    assert "TouchPattern" in ours and len(ours) >= 10
    for name, schema in ours.items():
        mine, theirs = _rules(schema), _rules(served[name])
        assert set(mine["properties"]) == set(theirs["properties"]), name
        for field in mine["properties"]:
            assert mine["properties"][field] == theirs["properties"][field], (name, field)
        assert mine == theirs, name


def test_the_services_own_pattern_is_sent_as_it_is(client: Client) -> None:
    pattern = service.TouchPattern.model_validate(STROKE.model_dump(exclude_unset=True))
    assert client.touch(pattern).path_length_cm == pytest.approx(9.6, rel=1e-6)


BLOCKER = """
import importlib.abc, sys
class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {"numpy", "scipy", "phantomtouch"}:
            raise ImportError(f"{name} must not be needed by the client")
sys.meta_path.insert(0, Blocker())
"""


def test_the_client_installs_and_runs_without_the_service_numpy_or_scipy(
    server: LiveServer, tmp_path: Path
) -> None:
    # Installed alone (its dependencies, httpx, pydantic and websockets, come from this
    # environment), with numpy, scipy and the service's package made unimportable.
    target = tmp_path / "site"
    install = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index"]
    install += ["--no-build-isolation", "--target", str(target), str(ROOT / "sdk_clients/python")]
    subprocess.run(install, check=True, capture_output=True, timeout=300, cwd=tmp_path)
    script = BLOCKER + (
        "import phantomtouch_client as pc\n"
        f"with pc.Client({server.url!r}) as pt:\n"
        "    job = pt.touch({'path': {'kind': 'polyline', 'points_cm': [[1.9, 12], [1.9, 2.4]]},"
        " 'speed_cm_s': 20.0})\n"
        "    print(job.path_length_cm)\n"
        "try:\n"
        "    still = {'kind': 'polyline', 'points_cm': [[0, 0]]}\n"
        "    pc.TouchPattern.model_validate({'path': still})\n"
        "except ValueError as exc:\n"
        "    print('refused:', 'exactly one of speed_cm_s or duration_s' in str(exc))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in {'numpy', 'scipy'}))\n"
    )
    result = subprocess.run(
        [sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, {str(target)!r})\n" + script],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["9.6", "refused:", "True", "[]"]


def _answers(*responses: httpx.Response) -> tuple[httpx.MockTransport, list[httpx.Request]]:
    sent: list[httpx.Request] = []
    queue = list(responses)

    def handler(request: httpx.Request) -> httpx.Response:
        sent.append(request)
        return queue.pop(0)

    return httpx.MockTransport(handler), sent


BUSY = {"error": {"code": "busy", "message": "the engine is busy", "fields": []}}
OK = {
    "status": "ok",
    "backend": "null",
    "engine": "running",
    "underruns": 0,
    "render_load_p99": 0.1,
}


def test_429_and_503_are_retried_after_retry_after_a_bounded_number_of_times() -> None:
    busy = httpx.Response(503, json=BUSY, headers={"Retry-After": "0.05"})
    transport, sent = _answers(busy, busy, httpx.Response(200, json=OK))
    with Client("http://test", transport=transport, retries=2) as pt:
        started = time.monotonic()
        assert pt.health().status == "ok"
        assert time.monotonic() - started >= 0.1  # waited as asked, twice
    assert len(sent) == 3
    transport, sent = _answers(busy, busy, busy)
    with Client("http://test", transport=transport, retries=2) as pt, pytest.raises(Busy):
        pt.health()
    assert len(sent) == 3  # the first try and two retries, then the refusal is raised


def test_no_retry_without_retry_after_or_beyond_the_longest_wait() -> None:
    for headers in ({}, {"Retry-After": "30"}):
        limited = httpx.Response(429, json=BUSY | {"error": BUSY["error"] | {"code": "x"}})
        limited.headers.update(headers)
        transport, sent = _answers(limited)
        client = Client("http://test", transport=transport, max_retry_wait_s=5.0)
        with client as pt, pytest.raises(Exception, match="busy"):
            pt.health()
        assert len(sent) == 1
    with pytest.raises(ParameterError):
        Client("http://test", retries=-1)


def test_async_client_retries_too() -> None:
    busy = httpx.Response(429, json=BUSY, headers={"Retry-After": "0"})

    async def main() -> None:
        sent: list[httpx.Request] = []
        queue = [busy, httpx.Response(200, json=OK)]

        def handler(request: httpx.Request) -> httpx.Response:
            sent.append(request)
            return queue.pop(0)

        async with AsyncClient("http://test", transport=httpx.MockTransport(handler)) as pt:
            assert (await pt.health()).status == "ok"
        assert len(sent) == 2

    asyncio.run(main())


def test_a_busy_engine_is_retried_after_its_retry_after(tmp_path: Path) -> None:
    # One voice at most: while a long touch plays, the next is refused 503 busy with
    # Retry-After: 1; the client waits that second once, then raises.
    env = {
        "PHANTOMTOUCH_MAX_VOICES": "1",
        "PHANTOMTOUCH_MAX_VOICES_PER_CLIENT": "2",
        "PHANTOMTOUCH_VOICE_POLICY": "refuse",
    }
    long = {"path": {"kind": "polyline", "points_cm": [[1.9, 7.2]]}, "duration_s": 30.0}
    server = LiveServer(tmp_path / "patterns.db", env=env)
    with server, Client(server.url, retries=1, max_retry_wait_s=2.0) as pt:
        pt.touch(long)
        started = time.monotonic()
        with pytest.raises(Busy) as refused:
            pt.touch(long)
        assert refused.value.status == 503
        assert time.monotonic() - started >= 1.0
