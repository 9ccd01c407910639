"""The wearer the output stage is fitted to, chosen while the service runs.

A wearer's offset of ``d`` dB on channel ``k`` is a gain of ``10 ** (d / 20)`` on that
channel, which the engine applies after the device's calibration and before its limiter
and hard clip (:meth:`~phantomtouch.engine.front.EngineFront.set_wearer_gains`), ramped
over ``WEARER_RAMP_S`` (20 ms) when it changes; switches (choose, clear) are limited to
``SWITCHES_PER_S`` a second after a burst of ``SWITCH_BURST``, beyond which they are
refused with 429 naming the limit. The device, its calibration and every plan stay those
of the un-fitted device; only the output stage's per-channel gains change.

One mix feeds the output stage, so one wearer and one band of their profile apply to the
whole service at a time: :class:`ActiveWearer` holds which, set at start by ``serve
--wearer NAME`` and changed at run time by ``PUT|DELETE /wearer`` and by a WebSocket
``hello`` that names a wearer (the latest choice wins, from whichever route it came).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from phantomtouch.engine.mixer import WEARER_RAMP_S
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema import DeviceProfile
from phantomtouch.schema.wearer import Band, WearerProfile, check_channels
from phantomtouch.service.errors import MissingReferenceError, RateLimitedError
from phantomtouch.service.store import PatternStore

if TYPE_CHECKING:
    from phantomtouch.engine.front import EngineFront

SWITCHES_PER_S = 2.0
"""Wearer switches (choose or clear) the service takes per second, sustained."""
SWITCH_BURST = 5
"""Switches it takes at once before the rate applies (a session choosing, clearing and
choosing again goes through)."""


def wearer_gains(device: DeviceProfile, profile: WearerProfile, band: Band) -> np.ndarray:
    """The output stage's per-channel gains for ``profile``'s offsets in ``band``.

    Returns
    -------
    ndarray, shape (device.channels,), float64
        ``10 ** (offset_db / 20)`` per channel (1 where the band names none).

    Raises
    ------
    ParameterError
        The profile names a channel the device does not have.
    """
    check_channels(profile, device.channels)
    offsets = np.array(profile.channel_offsets_db(band, device.channels), dtype=np.float64)
    return np.asarray(10.0 ** (offsets / 20.0), dtype=np.float64)


@dataclass(frozen=True)
class Choice:
    """The wearer in force: the profile's ``name`` and the ``band`` applied."""

    name: str
    band: Band


class ActiveWearer:
    """Which wearer the output stage is fitted to (host, any thread).

    Parameters
    ----------
    engine : EngineFront
    store : PatternStore
        Where the profiles are read from.
    """

    def __init__(self, engine: EngineFront, store: PatternStore) -> None:
        self._engine = engine
        self._store = store
        self._lock = threading.Lock()
        self.choice: Choice | None = None
        """The wearer in force, or None (the device's calibration alone)."""
        self.gains = np.ones(engine.channels, dtype=np.float64)
        """The per-channel gains in force (all 1 without a wearer)."""
        self._switches = float(SWITCH_BURST)
        self._switched_s = time.monotonic()

    def choose(self, name: str, band: Band, *, field: str = "name") -> Choice:
        """Fit the output stage to the stored profile ``name`` (its ``band``) from the next
        block on, ramped over ``WEARER_RAMP_S``.

        Raises
        ------
        RateLimitedError
            More than ``SWITCHES_PER_S`` switches a second (after a burst of
            ``SWITCH_BURST``): 429 naming the limit.
        MissingReferenceError
            ``name`` is not in the library, or names a channel the device lacks (422,
            naming ``field``).
        """
        with self._lock:
            profile = self._store.get_wearer(name)
            if profile is None:
                raise MissingReferenceError(
                    f"{field}={name!r} is not a stored wearer (GET /wearers)",
                    field=field,
                    value=name,
                )
            gains = self._gains(name, profile, band, field)
            self._take_switch()  # a refused choice is no switch
            self._set(gains)
            self.choice = Choice(name, band)
            return self.choice

    def clear(self) -> None:
        """Take the wearer off: the device's calibration alone from the next block on
        (a switch: :meth:`choose`'s rate limit applies)."""
        with self._lock:
            self._take_switch()
            self._set(np.ones(self._engine.channels))
            self.choice = None

    def _take_switch(self) -> None:
        """Spend one switch of the bucket (``SWITCH_BURST`` deep, refilled at
        ``SWITCHES_PER_S``), or refuse: 429 naming the limit (under the lock)."""
        now_s = time.monotonic()
        self._switches = min(
            float(SWITCH_BURST), self._switches + (now_s - self._switched_s) * SWITCHES_PER_S
        )
        self._switched_s = now_s
        if self._switches < 1.0:
            raise RateLimitedError(
                f"wearer switches are limited to {SWITCHES_PER_S:g} per second "
                f"(bursts of {SWITCH_BURST}); each ramps over "
                f"{WEARER_RAMP_S * 1000:g} ms: retry in "
                f"{(1.0 - self._switches) / SWITCHES_PER_S:.2f} s",
                field="wearer",
                value=SWITCHES_PER_S,
            )
        self._switches -= 1.0

    def stored(self, name: str, profile: WearerProfile) -> None:
        """``profile`` was stored as ``name``: re-apply it if it is the wearer in force."""
        with self._lock:
            if self.choice is not None and self.choice.name == name:
                self._apply(name, profile, self.choice.band, "name")

    def removed(self, name: str) -> None:
        """The profile ``name`` left the library: take it off if it is in force."""
        with self._lock:
            if self.choice is not None and self.choice.name == name:
                self._set(np.ones(self._engine.channels))
                self.choice = None

    def _apply(self, name: str, profile: WearerProfile, band: Band, field: str) -> None:
        self._set(self._gains(name, profile, band, field))

    def _gains(self, name: str, profile: WearerProfile, band: Band, field: str) -> np.ndarray:
        try:
            return wearer_gains(self._engine.device, profile, band)
        except ParameterError as exc:
            raise MissingReferenceError(
                f"{field}={name!r} does not fit the device: {exc}", field=field, value=name
            ) from exc

    def _set(self, gains: np.ndarray) -> None:
        self._engine.set_wearer_gains(gains)
        self.gains = gains


def check_start_wearer(
    name: str | None, band: Band, store: PatternStore, device: DeviceProfile
) -> None:
    """Check that ``serve --wearer NAME`` can be applied, before the service listens.

    Raises
    ------
    DeviceError
        The named wearer is not in the library, or does not fit the device.
    """
    if name is None:
        return
    profile = store.get_wearer(name)
    if profile is None:
        raise DeviceError(
            f"wearer={name!r} is not in the library {str(store.path)!r}; "
            "store it first (PUT /wearers/{name}) or start without --wearer"
        )
    try:
        wearer_gains(device, profile, band)
    except ParameterError as exc:
        raise DeviceError(f"wearer={name!r} does not fit the device: {exc}") from exc
