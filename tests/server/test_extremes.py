"""Hand-made extremes through ``POST /render``: finite samples, or a 422 naming the field.

The shapes of issue 37: splines with near-coincident points (the one that answered 500),
repeated polyline points, every point within 1e-12 cm, subnormal and 1e300 coordinates,
nearly collinear arcs, carriers at 24 kHz (the Nyquist frequency at 48 kHz). A path whose
points all merge (docs/algorithms.md, "Paths at the float's edge") is a touch that does
not move, the same through ``/touch``, ``/render``, the WebSocket and the CLI.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile
from fastapi.testclient import TestClient

from phantomtouch import DeviceProfile
from phantomtouch.cli import main
from phantomtouch.server import create_app
from tests.support.service import make_settings

CEILING = DeviceProfile.default().safety.ceiling
TINY = 5e-324
"""The smallest subnormal float."""


def touch(path: dict[str, Any], **fields: Any) -> dict[str, Any]:
    timing = {} if path["kind"] == "keyframes" or "duration_s" in fields else {"speed_cm_s": 50}
    return {"path": path, "fade_in_s": 0.05, "fade_out_s": 0.05, **timing, **fields}


def polyline(*points: tuple[float, float]) -> dict[str, Any]:
    return {"kind": "polyline", "points_cm": [list(p) for p in points]}


def spline(*points: tuple[float, float]) -> dict[str, Any]:
    return {"kind": "spline", "points_cm": [list(p) for p in points]}


def arc(start: tuple[float, float], through: tuple[float, float], end: tuple[float, float]) -> Any:
    return {"kind": "arc", "start_cm": start, "through_cm": through, "end_cm": end}


def keyframes(*frames: tuple[float, float, float]) -> dict[str, Any]:
    return {
        "kind": "keyframes",
        "keyframes": [{"t_s": t, "x_cm": x, "y_cm": y} for t, x, y in frames],
    }


RENDERED: dict[str, dict[str, Any]] = {
    "spline whose last step is below the float resolution of its length": touch(
        spline((1000.0, 0.0), (-1000.0, 0.0), (0.0, 0.0), (0.0, 1e-300)), speed_cm_s=1000
    ),
    "spline the fuzzer found (subnormal and tiny coordinates after a long chord)": touch(
        spline(
            (1000.0, -1.1125369292536007e-308),
            (8.0856167324773755e-78, -538.2908938689111),
            (-7.057672454294669e-86, 2.225073858507203e-309),
            (1.388958878006414e-166, 3.3597888809466037e-82),
        ),
        speed_cm_s=1000,
    ),
    "spline with two points one ulp apart": touch(
        spline((1.9, 12.0), (1.9, 12.000000000000002), (3.0, 7.0), (1.9, 2.4))
    ),
    "polyline with repeated points": touch(
        polyline((1.9, 12.0), (1.9, 12.0), (1.9, 12.0), (3.8, 7.2), (3.8, 7.2), (1.9, 2.4))
    ),
    "polyline with every point within 1e-12 cm": touch(
        polyline((1.9, 7.0), (1.9 + 1e-13, 7.0), (1.9, 7.0 + 1e-13)), duration_s=0.5
    ),
    "spline with every point within 1e-12 cm": touch(
        spline((1.9, 7.0), (1.9 + 1e-13, 7.0), (1.9, 7.0 - 1e-13)), duration_s=0.5
    ),
    "arc with every point within 1e-12 cm": touch(
        arc((1.9, 7.0), (1.9 + 1e-13, 7.0), (1.9, 7.0 + 1e-13)), duration_s=0.5
    ),
    "polyline of subnormal coordinates": touch(
        polyline((TINY, 0.0), (0.0, TINY), (2.2250738585072014e-308, 1e-310)), duration_s=0.5
    ),
    "spline of subnormal coordinates": touch(
        spline((TINY, 0.0), (0.0, TINY), (1e-320, 1e-320)), duration_s=0.5
    ),
    "arc of subnormal coordinates": touch(
        arc((TINY, 0.0), (0.0, TINY), (1e-320, 0.0)), duration_s=0.5
    ),
    "keyframes a subnormal time apart": touch(keyframes((0.0, 1.9, 7.0), (TINY, 1.9, 7.0))),
    "keyframes a subnormal distance and time apart": touch(
        keyframes((0.0, 1.9, 7.0), (TINY, 1.9, 7.0 + 1e-13), (0.3, 1.9, 9.0))
    ),
    "nearly collinear arc (radius 1e9 cm)": touch(arc((0.5, 1.0), (0.5 + 2e-8, 7.5), (0.5, 14.0))),
    "sine just below 24 kHz": touch(
        polyline((1.9, 12.0), (1.9, 2.4)), carrier={"kind": "sine", "freq_hz": 23999.0}
    ),
}

REFUSED: dict[str, tuple[dict[str, Any], str]] = {
    "polyline at 1e300 cm": (touch(polyline((1e300, 0.0), (0.0, 1.0))), "path.points_cm[0]"),
    "spline at -1e300 cm": (touch(spline((0.0, 1.0), (2.0, -1e300))), "path.points_cm[1]"),
    "arc at 1e300 cm": (touch(arc((0.0, 0.0), (1e300, 1.0), (2.0, 0.0))), "path.through_cm"),
    "keyframe at 1e300 cm": (touch(keyframes((0.0, 1e300, 1.0))), "path.keyframes[0].x_cm"),
    "arc collinear within 1e-9 of its scale": (
        touch(arc((0.5, 1.0), (0.5 + 1e-8, 7.5), (0.5, 14.0))),
        "path.through_cm",
    ),
    "arc whose ends coincide": (touch(arc((0.5, 1.0), (2.0, 7.5), (0.5, 1.0))), "path.end_cm"),
    "sine at 24 kHz": (
        touch(polyline((1.9, 12.0), (1.9, 2.4)), carrier={"kind": "sine", "freq_hz": 24000.0}),
        "carrier.freq_hz",
    ),
    "combined carrier at 24 kHz": (
        touch(polyline((1.9, 12.0), (1.9, 2.4)), carrier={"kind": "combined", "freq_hz": 24000.0}),
        "carrier.freq_hz",
    ),
    "noise band up to 24 kHz": (
        touch(
            polyline((1.9, 12.0), (1.9, 2.4)),
            carrier={"kind": "noise", "low_hz": 100.0, "high_hz": 24000.0},
        ),
        "carrier.high_hz",
    ),
    "keyframes a subnormal time apart that move": (
        touch(keyframes((0.0, 1.9, 7.0), (TINY, 1.9, 8.0))),
        "path.keyframes[1].t_s",
    ),
}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("extremes")
    with TestClient(create_app(make_settings(folder))) as client:
        yield client


@pytest.mark.parametrize("name", sorted(RENDERED))
def test_the_extreme_renders_finite_samples_within_the_ceiling(
    client: TestClient, name: str
) -> None:
    answer = client.post("/render", json=RENDERED[name])
    assert answer.status_code == 200, answer.text
    samples, _ = soundfile.read(io.BytesIO(answer.content), dtype="float32", always_2d=True)
    assert len(samples) > 0 and np.all(np.isfinite(samples))
    assert 0.0 < np.max(np.abs(samples)) <= CEILING


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_the_extreme_is_refused_naming_its_field(client: TestClient, name: str) -> None:
    body, field = REFUSED[name]
    answer = client.post("/render", json=body)
    assert answer.status_code == 422, answer.text
    fields = [item["field"] for item in answer.json()["error"]["fields"]]
    assert any(f.startswith(field) for f in fields), (field, answer.json())


# --- a path that collapses to a point, through every input ---------------------------

COLLAPSED = {
    "polyline": polyline((1.9, 7.0), (1.9 + 1e-13, 7.0)),
    "spline": spline((1.9, 7.0), (1.9, 7.0 + 1e-13), (1.9 + 1e-13, 7.0)),
    "arc": arc((1.9, 7.0), (1.9 + 1e-13, 7.0), (1.9, 7.0 + 1e-13)),
}


def _cli_plan(body: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Any:
    (tmp_path / "touch.json").write_text(json.dumps(body))
    code = main(["render", str(tmp_path / "touch.json"), "-o", str(tmp_path / "t.wav"), "--json"])
    out = capsys.readouterr()
    return json.loads(out.out) if code == 0 else (code, out.err)


@pytest.mark.parametrize("kind", sorted(COLLAPSED))
def test_a_collapsed_path_is_a_still_touch_on_every_input(
    client: TestClient, kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    body = {"path": COLLAPSED[kind], "duration_s": 1.5}
    rendered = client.post("/render", json=body, headers={"Accept": "application/json"}).json()
    touched = client.post("/touch", json=body).json()
    with client.websocket_connect("/ws") as ws:
        ws.send_json({"type": "play", "id": "p", **body})
        played = ws.receive_json()["result"]
    offline = _cli_plan(body, tmp_path, capsys)
    for plan in (rendered, touched, played, offline):
        assert (plan["path_length_cm"], plan["speed_cm_s"], plan["duration_s"]) == (0.0, 0.0, 1.5)
    client.post("/stop")


@pytest.mark.parametrize("kind", sorted(COLLAPSED))
def test_a_collapsed_path_without_time_is_refused_alike_on_every_input(
    client: TestClient, kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    body = {"path": COLLAPSED[kind], "speed_cm_s": 5.0, "fade_in_s": 0.0, "fade_out_s": 0.0}
    for answer in (client.post("/render", json=body), client.post("/touch", json=body)):
        assert answer.status_code == 422
        assert answer.json()["error"]["fields"][0]["field"] == "duration_s"
    with client.websocket_connect("/ws") as ws:
        ws.send_json({"type": "play", "id": "p", **body})
        refused = ws.receive_json()
    assert refused["fields"][0]["field"] == "duration_s", refused
    code, err = _cli_plan(body, tmp_path, capsys)
    assert code == 2 and "duration_s=0: the pattern has zero duration" in err
