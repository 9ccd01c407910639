"""Prometheus metrics of the requests and, at scrape time, of the engine."""

from __future__ import annotations

from fastapi import FastAPI, Response
from fastapi.testclient import TestClient

from phantomtouch.service.metrics import CONTENT_TYPE, Metrics, MetricsMiddleware

STATUS = {
    "active_voices": 3,
    "active_contacts": [{"owner": "ws-0", "contact": "L", "x_cm": 1.0, "y_cm": 2.0}],
    "underruns": 2,
    "late_commands": 5,
    "inline_renders": 7,
    "nonfinite_voices": 2,
    "overrun_voices": 1,
    "dc_blocked_blocks": 9,
    "limited_blocks": 0,
    "muted_blocks": 4,
    "peak": 0.25,
    "queue_depth": 1,
    "levels": [0.25, 0.0],
    "render_load_p99": 0.125,
    "render_load_max": 0.5,
    "callback_p50_s": 0.0002,
    "callback_p99_s": 0.001,
    "callback_max_s": 0.004,
    "period_frames": 64,
    "voice_capacity": 40,
    "voice_cost": 0.0125,
    "render_budget": 0.5,
    "state": "stalled",
    "restarts": 1,
}


def _app(metrics: Metrics) -> FastAPI:
    app = FastAPI()

    @app.get("/items/{item}")
    async def item(item: int) -> dict[str, int]:
        return {"item": item}

    @app.get("/metrics")
    async def scrape() -> Response:
        return Response(metrics.exposition(), media_type=CONTENT_TYPE)

    app.add_middleware(MetricsMiddleware, metrics=metrics)
    return app


def test_requests_by_route_template_and_status() -> None:
    metrics = Metrics()
    with TestClient(_app(metrics)) as client:
        client.get("/items/1")
        client.get("/items/2")
        client.get("/items/x")
        text = client.get("/metrics").text
    assert (
        'phantomtouch_http_requests_total{method="GET",route="/items/{item}",status="200"} 2.0'
        in text
    )
    assert 'route="/items/{item}",status="422"} 1.0' in text
    assert 'phantomtouch_http_request_duration_seconds_count{route="/items/{item}"} 3.0' in text


def test_engine_figures_are_read_at_scrape_time() -> None:
    metrics = Metrics()
    metrics.watch_engine(lambda: STATUS)
    text = metrics.exposition().decode()
    assert "phantomtouch_active_voices 3.0" in text
    assert "phantomtouch_active_contacts 1.0" in text
    assert "phantomtouch_underruns_total 2.0" in text
    assert "phantomtouch_late_commands_total 5.0" in text
    assert "phantomtouch_inline_renders_total 7.0" in text
    assert 'phantomtouch_silenced_voices_total{reason="non_finite"} 2.0' in text
    assert 'phantomtouch_silenced_voices_total{reason="over_budget"} 1.0' in text
    assert "phantomtouch_dc_blocked_blocks_total 9.0" in text
    assert "phantomtouch_muted_blocks_total 4.0" in text
    assert "phantomtouch_peak_level 0.25" in text
    assert 'phantomtouch_channel_peak_level{channel="1"} 0.25' in text
    assert 'phantomtouch_render_load{quantile="0.99"} 0.125' in text
    assert 'phantomtouch_render_load{quantile="1"} 0.5' in text
    assert 'phantomtouch_callback_seconds{quantile="0.5"} 0.0002' in text
    assert 'phantomtouch_callback_seconds{quantile="0.99"} 0.001' in text
    assert 'phantomtouch_callback_seconds{quantile="1"} 0.004' in text
    assert "phantomtouch_period_frames 64.0" in text
    assert "phantomtouch_voice_capacity 40.0" in text
    assert "phantomtouch_voice_cost 0.0125" in text
    assert "phantomtouch_render_budget 0.5" in text
    assert "phantomtouch_engine_running 0.0" in text
    assert "phantomtouch_engine_restarts_total 1.0" in text
    metrics.watch_engine(None)
    assert "phantomtouch_active_voices" not in metrics.exposition().decode()


def test_two_apps_do_not_share_a_registry() -> None:
    first, second = Metrics(), Metrics()
    first.ws_messages.labels("in", "move").inc()
    assert "phantomtouch_ws_messages_total" in first.exposition().decode()
    assert 'direction="in"' not in second.exposition().decode()
