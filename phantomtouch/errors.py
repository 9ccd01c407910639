"""The exception tree of phantomtouch.

::

    PhantomTouchError              root: every error the package raises on purpose
    ├── ParameterError(ValueError) a value is outside its allowed range
    │   └── FieldError             ... of a document, at a field path it names
    ├── DeviceError                a device profile or the sound card is unusable
    ├── EngineBusyError            the engine's bounded command queue is full
    └── ProtocolError              a client broke the WebSocket protocol

Messages name the parameter, the value and what is allowed, for example
``ParameterError("speed_cm_s=0.0 must be > 0 and <= 1000")``. The server maps each class
to one HTTP status and one WebSocket close code, in one place.
"""

from __future__ import annotations

import sys


class PhantomTouchError(Exception):
    """Root of every error raised on purpose by phantomtouch."""


class ParameterError(PhantomTouchError, ValueError):
    """A parameter is outside its allowed range; the message names it and its value."""


class FieldError(ParameterError):
    """A document (a ``.tact`` project, a deployment) refused at one of its fields.

    ``field`` is the path of the field at fault inside the document as given
    (``tracks[0].effects[2].startTime``; ``""``: the document as a whole) and ``value`` its
    value (None when it is missing or too large to repeat); the message names both and
    what is allowed. The server answers it naming ``field``.
    """

    def __init__(self, message: str, *, field: str, value: object = None) -> None:
        super().__init__(message)
        self.field = field
        self.value = value


class DeviceError(PhantomTouchError):
    """A device profile is degenerate, or the sound card cannot be opened or used."""


class EngineBusyError(PhantomTouchError):
    """The engine's command queue is full; the command was not accepted."""


class ProtocolError(PhantomTouchError):
    """A client sent a message that the protocol does not allow in its state."""


def install_hint(extra: str) -> str:
    """How to install an optional part (an extra of ``pyproject.toml``) into the checkout's
    ``.venv``, for an error message: no package index holds phantomtouch, it is installed
    from its checkout. Runs on any thread."""
    if sys.platform == "win32":
        return (
            "in the checkout, py scripts\\run.py installs it "
            f"(or .venv\\Scripts\\pip install -e '.[{extra}]')"
        )
    return (
        f"in the checkout, scripts/install installs it (or .venv/bin/pip install -e '.[{extra}]')"
    )
