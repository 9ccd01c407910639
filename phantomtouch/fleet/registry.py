"""The armband registry: a JetStream key–value bucket whose entries expire.

Each node rewrites its :class:`~phantomtouch.fleet.records.ArmbandRecord` every
``heartbeat_s``; the bucket's TTL (``ttl_s``, its streams' maximum age) removes the key of
a node that stopped doing so. A key that exists is an armband online; a node that shuts
down cleanly purges its key at once. A gateway reads it through a watch
(:class:`~phantomtouch.fleet.registry_view.RegistryView`), never key by key.
"""

from __future__ import annotations

import logging
from typing import Any

from pydantic import ValidationError

from phantomtouch.fleet.records import ArmbandRecord
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.subjects import REGISTRY_BUCKET

logger = logging.getLogger("phantomtouch.fleet")

REPLICAS = 3
"""Copies of the registry in a cluster of three or more servers (one on a lone server)."""


async def open_bucket(js: Any, settings: FleetSettings) -> Any:
    """The registry bucket, created if missing: replicated on three servers if it can be,
    and readable from any replica (direct get), so reads go on while a server is down."""
    import nats.js.errors

    try:
        return await js.key_value(REGISTRY_BUCKET)
    except nats.js.errors.BucketNotFoundError:
        pass
    try:
        return await js.create_key_value(
            bucket=REGISTRY_BUCKET, ttl=settings.ttl_s, history=1, replicas=REPLICAS, direct=True
        )
    except nats.js.errors.APIError as exc:
        logger.info("fleet: registry on one server only (%s replicas refused: %s)", REPLICAS, exc)
        return await js.create_key_value(
            bucket=REGISTRY_BUCKET, ttl=settings.ttl_s, history=1, replicas=1, direct=True
        )


def read_record(value: bytes | None) -> ArmbandRecord | None:
    """A record from a bucket value; None for one that does not read as a record."""
    if not value:
        return None
    try:
        return ArmbandRecord.model_validate_json(value)
    except ValidationError:
        logger.warning("fleet: a registry entry does not read as an armband record; ignored")
        return None
