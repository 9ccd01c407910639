"""The armband registry: a JetStream key–value bucket whose entries expire.

Each node rewrites its :class:`~phantomtouch.fleet.records.ArmbandRecord` every
``heartbeat_s``; the bucket's TTL (``ttl_s``, its streams' maximum age) removes the key of
a node that stopped doing so. A key that exists is an armband online; a node that shuts
down cleanly purges its key at once.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from pydantic import ValidationError

from phantomtouch.errors import DeviceError
from phantomtouch.fleet.errors import ArmbandUnavailableError
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


LISTING_PASSES = 2
"""Passes over the bucket's keys when listing the armbands online. One pass can miss a
key: the bucket keeps one revision per key, and a heartbeat that replaces a record while
the listing reads the bucket removes the revision the listing was about to see (and may
show another key twice). Two passes, merged, miss a key only if it is replaced during
both."""


class Registry:
    """Reads the registry for a gateway, caching each armband found for ``cache_s``.

    An armband that is not found is looked up again on every call, so a node that just
    joined is found at once; one found stays cached for at most ``cache_s``, after which
    its key is read again (a node that died is refused by NATS in the meantime: nobody
    answers its subjects). While the registry cannot be read (NATS is failing over), the
    last record read stands in: the addressed node's own answer decides.
    """

    def __init__(self, kv: Any, *, cache_s: float) -> None:
        self.kv = kv
        self.cache_s = cache_s
        self._cache: dict[str, tuple[float, ArmbandRecord]] = {}

    async def lookup(self, armband: str) -> ArmbandRecord | None:
        """The armband's record, or None when it is not online."""
        import nats.errors
        import nats.js.errors

        cached = self._cache.get(armband)
        now_s = time.monotonic()
        if cached is not None and now_s - cached[0] < self.cache_s:
            return cached[1]
        try:
            entry = await self.kv.get(armband)
        except (nats.js.errors.KeyNotFoundError, nats.js.errors.KeyDeletedError):
            self._cache.pop(armband, None)
            return None
        except (nats.errors.Error, TimeoutError) as exc:
            if cached is None:
                raise ArmbandUnavailableError(
                    armband, f"the registry cannot be read now ({type(exc).__name__})"
                ) from None
            return cached[1]
        record = read_record(entry.value)
        if record is None:
            self._cache.pop(armband, None)
            return None
        self._cache[armband] = (now_s, record)
        return record

    async def online(self) -> list[ArmbandRecord]:
        """Every armband online, by id.

        Raises
        ------
        DeviceError
            The registry cannot be read now (503 ``device``).
        """
        import nats.errors
        import nats.js.errors

        keys: set[str] = set()
        for _ in range(LISTING_PASSES):
            try:
                keys.update(await self.kv.keys())
            except nats.js.errors.NoKeysError:
                continue
            except (nats.errors.Error, TimeoutError) as exc:
                raise DeviceError(
                    f"fleet: the registry cannot be read now ({type(exc).__name__}); retry"
                ) from None
        records = [await self.lookup(key) for key in sorted(keys)]
        return [record for record in records if record is not None]

    def forget(self, armband: str) -> None:
        """Drop a cached record (its node did not answer)."""
        self._cache.pop(armband, None)
