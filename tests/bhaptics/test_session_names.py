"""The SDK1 session's names (phantomtouch/bhaptics/session.py) are its handle's named plays,
over a real engine rendering into a capture sink at real-time pace: ``ActiveKeys`` follows
the engine's job table and the stop, ``turnOff`` stops one name alone, and a connection
shows at most ``MAX_ACTIVE_FRAMES`` frames (the newest ends the oldest)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from phantomtouch.bhaptics.session import MAX_ACTIVE_FRAMES, PlayerSession, PointBudget, prepare
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.engine import Engine
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, Handle, policy_table
from tests.bhaptics.test_standin_live import dot_project
from tests.support.service import make_settings

DEVICE = DeviceProfile.default()


def frame(key: str, index: int = 2, duration_ms: int = 3000) -> dict[str, Any]:
    return {
        "type": "frame",
        "key": key,
        "Frame": {
            "position": "ForearmL",
            "dotPoints": [{"index": index, "intensity": 100}],
            "durationMillis": duration_ms,
        },
    }


async def send(session: PlayerSession, handle: Handle, message: dict[str, Any]) -> list[str]:
    """Apply ``message`` as the listener does; the status's ``ActiveKeys`` after it."""
    text = json.dumps(message)
    arrival = handle.receive(len(text)).arrival
    assert arrival is not None
    assert await session.apply(prepare(text), arrival) == 0
    session.expire()
    active = session.status()["ActiveKeys"]
    assert isinstance(active, list)
    return active


def run(tmp_path: Path, scenario: Any) -> None:
    async def main() -> None:
        with Engine(DEVICE, CaptureSink(DEVICE, realtime=True)) as engine:
            admission = Admission(engine, policy_table(make_settings(tmp_path)))
            handle = admission.open("bhaptics", "1-game", principal="bhaptics:127.0.0.1")
            session = PlayerSession(handle, ArmMap(), budget=PointBudget(), changed=lambda: None)
            try:
                await scenario(engine, admission, handle, session)
            finally:
                session.close()

    asyncio.run(main())


def test_active_keys_follow_the_job_table_and_turn_off_stops_one_name(tmp_path: Path) -> None:
    async def scenario(
        engine: Engine, admission: Admission, handle: Handle, session: PlayerSession
    ) -> None:
        project = dot_project("ForearmL", 1, 3000)
        await send(session, handle, {"Register": [{"key": "long", "project": project}]})
        keys = [{"type": "key", "key": "long", "Parameters": {"altKey": n}} for n in "abc"]
        assert await send(session, handle, {"Submit": keys}) == ["a", "b", "c"]
        jobs = {play.name: play.jobs for play in handle.named.plays()}
        assert all(jobs.values())
        for job in jobs["a"]:  # as DELETE /jobs/{id} does: the session is told nothing
            assert engine.stop(job)
        session.expire()
        assert session.status()["ActiveKeys"] == ["b", "c"]
        assert await send(session, handle, {"Submit": [{"type": "turnOff", "key": "b"}]}) == ["c"]
        states = {name: [engine.job_state(j).state for j in ids] for name, ids in jobs.items()}  # type: ignore[union-attr]
        assert states["b"] == ["stopped"] and states["c"] != ["stopped"]

    run(tmp_path, scenario)


def test_a_stop_ends_every_name_and_voids_a_frame_sent_before_it(tmp_path: Path) -> None:
    async def scenario(
        engine: Engine, admission: Admission, handle: Handle, session: PlayerSession
    ) -> None:
        assert await send(session, handle, {"Submit": [frame("held")]}) == ["held"]
        assert handle.contacts()
        text = json.dumps({"Submit": [frame("late")]})
        arrival = handle.receive(len(text)).arrival
        assert arrival is not None
        admission.stop_all()  # POST /stop, after the message came and before it is applied
        await session.apply(prepare(text), arrival)
        session.expire()
        assert session.status()["ActiveKeys"] == []
        assert handle.contacts() == []

    run(tmp_path, scenario)


def test_the_newest_frame_past_the_bound_ends_the_oldest(tmp_path: Path) -> None:
    async def scenario(
        engine: Engine, admission: Admission, handle: Handle, session: PlayerSession
    ) -> None:
        names = [f"f{k:02d}" for k in range(MAX_ACTIVE_FRAMES + 1)]
        for start in range(0, len(names), 8):
            await send(session, handle, {"Submit": [frame(n) for n in names[start : start + 8]]})
        active = session.status()["ActiveKeys"]
        assert active == sorted(names[1:])  # f00, the oldest, ended
        await send(session, handle, {"Submit": [frame("f01", index=3)]})  # re-shown: newest
        await send(session, handle, {"Submit": [frame("new")]})
        assert "f01" in session.status()["ActiveKeys"]
        assert "f02" not in session.status()["ActiveKeys"]

    run(tmp_path, scenario)
