"""The NATS subjects and the registry bucket of a fleet (docs/fleet.md).

Every subject starts with :data:`PREFIX`; armband ids and site names are single subject
tokens (:data:`NAME_REGEX`), so that no id can reach into another armband's subjects.

=====================================  ==============  =====================================
subject                                pattern         what
=====================================  ==============  =====================================
``phantomtouch.armband.ID.touch``      request–reply   a touch; answers ``{status, body}``
``phantomtouch.armband.ID.contact``    publish         ``down``/``move``/``up``/``ping``/
                                                       ``release`` of a remote owner
``phantomtouch.armband.ID.stop``       request–reply   this armband off (or one ``job_id``)
``phantomtouch.armband.ID.clock``      request–reply   the node's wall clock now
``phantomtouch.released.ID.OWNER``     publish         armband ``ID`` let go of ``OWNER``'s
                                                       contacts (``{contacts, reason}``)
``phantomtouch.site.SITE.stop``        request–reply   every armband of the site off
``phantomtouch.stop``                  request–reply   every armband off (each one answers)
=====================================  ==============  =====================================

The registry is the JetStream key–value bucket :data:`REGISTRY_BUCKET`: one key per
armband id, one JSON record (:class:`~phantomtouch.fleet.records.ArmbandRecord`) per
heartbeat, expiring after the bucket's TTL.
"""

from __future__ import annotations

import re

from phantomtouch.errors import ParameterError

PREFIX = "phantomtouch"
REGISTRY_BUCKET = "phantomtouch_armbands"
NAME_REGEX = r"^[A-Za-z0-9_-]{1,64}$"
"""Armband ids and site names: 1 to 64 letters, digits, '_' and '-'."""
_NAME = re.compile(NAME_REGEX)
_OWNER = re.compile(r"^[A-Za-z0-9_-]{1,128}$")
"""Owners whose releases are published: those a gateway names (``gw-ID-N``), one subject
token each, so that no owner reaches into another's subject."""
STOP_ALL = f"{PREFIX}.stop"


def check_name(field: str, value: str) -> str:
    """``value`` if it is a valid armband id or site name, else :class:`ParameterError`."""
    if not isinstance(value, str) or not _NAME.fullmatch(value):
        raise ParameterError(
            f"{field}={value!r}: must be 1 to 64 letters, digits, '_' or '-' "
            "(it becomes one NATS subject token)"
        )
    return value


def touch(armband: str) -> str:
    return f"{PREFIX}.armband.{armband}.touch"


def contact(armband: str) -> str:
    return f"{PREFIX}.armband.{armband}.contact"


def stop_armband(armband: str) -> str:
    return f"{PREFIX}.armband.{armband}.stop"


def clock(armband: str) -> str:
    return f"{PREFIX}.armband.{armband}.clock"


def stop_site(site: str) -> str:
    return f"{PREFIX}.site.{site}.stop"


def released(armband: str, owner: str) -> str | None:
    """The subject ``armband``'s node tells ``owner``'s releases on; None when ``owner``
    is not one subject token (:data:`_OWNER`), whose releases are not told."""
    return f"{PREFIX}.released.{armband}.{owner}" if _OWNER.fullmatch(owner) else None


def released_to(owner: str) -> str | None:
    """The subject pattern of ``owner``'s releases on every armband (a gateway listens on
    it for one connection); None as :func:`released`."""
    return released("*", owner)


def released_armband(subject: str) -> str:
    """The armband a :func:`released` subject names."""
    return subject.split(".")[2]
