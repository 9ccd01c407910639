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
