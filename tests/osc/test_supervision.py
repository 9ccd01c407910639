"""The OSC receive thread is supervised: if it dies anyway, its contacts are released at
once, it is started again, and ``/health`` names the input."""

from __future__ import annotations

from typing import Any

from phantomtouch.osc.bridge import OscBridge
from tests.osc.test_service_osc import service, status, wait_for

__all__ = ["service"]


def test_a_dead_receive_thread_releases_its_contacts_restarts_and_shows_in_health(
    service: Any,
) -> None:
    client, osc, _ = service
    bridge = client.app.state.service.inputs["osc"].__self__
    assert isinstance(bridge, OscBridge)
    osc.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 0.5])
    assert wait_for(lambda: status(client)["active_contacts"])
    assert client.get("/health").json()["status"] == "ok"
    first = bridge._thread

    def fail(data: bytes, peer: tuple[str, int], now_s: float) -> None:
        # A fault outside every per-message guard: the thread's loop itself dies.
        del bridge._datagram
        raise RuntimeError("injected fault")

    bridge._datagram = fail  # type: ignore[method-assign]
    osc.send_message("/phantomtouch/contact/finger", [1.9, 7.0, 0.5])
    # Released at once by the supervisor, not by the map's 1 s watchdog later.
    assert wait_for(lambda: not status(client)["active_contacts"], timeout_s=30.0)
    assert bridge.watchdog_releases == 0
    health = wait_for(lambda: client.get("/health").json()["inputs"]["osc"]["restarts"] == 1)
    assert health
    health = client.get("/health").json()
    assert health["status"] == "degraded"
    assert health["degraded_inputs"] == ["osc"]
    assert health["inputs"]["osc"]["last_failure"] == "RuntimeError: injected fault"
    assert wait_for(lambda: bridge._thread is not first and bridge._thread.is_alive())
    assert wait_for(lambda: client.get("/health").json()["inputs"]["osc"]["state"] == "running")
    assert "phantomtouch_osc_restarts_total 1.0" in client.get("/metrics").text
    # The new thread serves: a contact goes down again.
    osc.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 0.5])
    assert wait_for(lambda: status(client)["active_contacts"])
