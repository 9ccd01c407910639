"""``create_app(settings)``: the FastAPI app of the touch service.

Nothing heavy happens at import or in ``create_app``; the lifespan loads the device
profile, opens the pattern store, starts the engine (its audio thread) and stops both
on shut-down.
"""

from __future__ import annotations

import asyncio
import gc
import logging
from collections.abc import AsyncIterator, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.utils import get_openapi
from fastapi.staticfiles import StaticFiles

from phantomtouch import __version__
from phantomtouch.schema import DeviceProfile
from phantomtouch.server.routes import (
    clips,
    docs,
    info,
    patterns,
    render,
    tact,
    touch,
    wearer,
    wearers,
    web,
    workspaces,
    ws,
)
from phantomtouch.service import errors
from phantomtouch.service.arrivals import ArrivalMiddleware
from phantomtouch.service.bodies import merge_components
from phantomtouch.service.engine_access import describe_output, open_engine
from phantomtouch.service.lane import running_lane
from phantomtouch.service.limits import BodyLimitMiddleware, TokenMiddleware
from phantomtouch.service.metrics import Metrics, MetricsMiddleware
from phantomtouch.service.origin import (
    ContentTypeMiddleware,
    HostOriginMiddleware,
    HostPolicy,
    OriginPolicy,
    Refusals,
)
from phantomtouch.service.running import Attachment, Service
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore
from phantomtouch.service.wearers import check_start_wearer

logger = logging.getLogger("phantomtouch.server")

DESCRIPTION = """Touch on the forearm for VR scenes and touch research.

Errors are `{"error": {"code", "message", "fields": [{field, value, message}]}}`; the
wire protocol, the WebSocket `/ws` included, is described in `docs/protocol.md`.
"""


def _lifespan(settings: Settings, metrics: Metrics, attach: Sequence[Attachment]) -> Any:
    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        device = (
            DeviceProfile.load(settings.device_profile)
            if settings.device_profile
            else DeviceProfile.default()
        )
        store = PatternStore.open(settings.db_path)
        try:
            check_start_wearer(settings.wearer, settings.wearer_band, store, device)
            engine = open_engine(settings, device)
        except BaseException:
            store.close()
            raise
        service = Service(settings, engine.device, engine, store, metrics)
        if settings.wearer is not None:
            service.wearer.choose(settings.wearer, settings.wearer_band, field="wearer")
        service.loop = asyncio.get_running_loop()
        app.state.service = service
        logger.info("phantomtouch: %s; patterns in %s", describe_output(engine), store.path)
        metrics.watch_engine(lambda: engine.status().to_dict())
        try:
            async with AsyncExitStack() as attached:
                attached.enter_context(running_lane(service))
                for attachment in attach:
                    await attached.enter_async_context(attachment(service))
                # what start-up made is never scanned again: a full collection, which
                # holds the interpreter (the event loop, the contact lane) while it runs,
                # looks only at what the service made since (docs/engine.md, Threads)
                gc.freeze()
                try:
                    yield
                finally:
                    gc.unfreeze()  # collectable again once the service closes
        finally:
            metrics.watch_engine(None)
            engine.close()
            store.close()

    return lifespan


def _openapi(app: FastAPI, settings: Settings) -> Any:
    def schema() -> dict[str, Any]:
        if app.openapi_schema is None:
            document = get_openapi(
                title=app.title,
                version=app.version,
                description=app.description,
                routes=app.routes,
                tags=app.openapi_tags,
            )
            merge_components(document)
            if settings.token is not None:
                document.setdefault("components", {})["securitySchemes"] = {
                    "bearer": {"type": "http", "scheme": "bearer"}
                }
                document["security"] = [{"bearer": []}]
                document["paths"]["/health"]["get"]["security"] = []
            app.openapi_schema = document
        return app.openapi_schema

    return schema


def create_app(settings: Settings | None = None, *, attach: Sequence[Attachment] = ()) -> FastAPI:
    """Build the app; the engine and the store open when it starts (lifespan), then each
    of ``attach`` is entered with the running service, in order (the OSC bridge,
    :func:`phantomtouch.osc.service_link.attach`; an armband node joining a fleet,
    :func:`phantomtouch.fleet.node.attach`), and left in the reverse order before the
    engine and the store close."""
    settings = settings or Settings()
    metrics = Metrics()
    app = FastAPI(
        title="phantomtouch",
        version=__version__,
        description=DESCRIPTION,
        lifespan=_lifespan(settings, metrics, attach),
        separate_input_output_schemas=False,
        docs_url=None,
        redoc_url=None,
        openapi_tags=[
            {"name": "touch", "description": "Play and stop touches."},
            {"name": "patterns", "description": "The pattern library (SQLite)."},
            {"name": "bhaptics", "description": "bHaptics SDK2 workspaces: games' events."},
            {"name": "wearers", "description": "Wearer profiles: felt intensity per actuator."},
            {"name": "render", "description": "Offline rendering."},
            {"name": "info", "description": "Device, presets, clock, health, metrics."},
        ],
    )
    app.state.settings = settings
    errors.install(app)
    for module in (
        touch,
        patterns,
        clips,
        tact,
        workspaces,
        wearers,
        wearer,
        render,
        info,
        ws,
        web,
        docs,
    ):
        app.include_router(module.router)
    app.mount(docs.ASSETS_PATH, StaticFiles(directory=docs.ASSETS_DIR), name="docs-assets")
    if web.STATIC_DIR.is_dir():
        app.mount("/static", StaticFiles(directory=web.STATIC_DIR), name="static")
    refusals = Refusals(metrics)
    # Outermost last: arrival, metrics, Host and Origin, CORS, token, content type, body size.
    app.add_middleware(BodyLimitMiddleware, max_bytes=settings.max_body_bytes)
    app.add_middleware(ContentTypeMiddleware, refusals=refusals)
    if settings.token is not None:
        app.add_middleware(TokenMiddleware, token=settings.token)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "PUT", "DELETE"],
            allow_headers=["Authorization", "Content-Type", "Accept"],
        )
    app.add_middleware(
        HostOriginMiddleware,
        hosts=HostPolicy.build(settings.host, settings.allowed_hosts),
        origins=OriginPolicy.build(settings.cors_origins),
        refusals=refusals,
    )
    app.add_middleware(MetricsMiddleware, metrics=metrics)
    app.add_middleware(ArrivalMiddleware)  # outermost: a request's arrival, before its body
    app.openapi = _openapi(app, settings)  # type: ignore[method-assign]
    return app
