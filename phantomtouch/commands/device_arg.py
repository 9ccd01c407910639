"""A device profile named on the command line (``--device PATH``)."""

from __future__ import annotations

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema import DeviceProfile


def load_device(path: str | None) -> DeviceProfile:
    """The profile at ``path`` (None: the paper's); a bad file is bad input (exit 2).

    Raises
    ------
    ParameterError
        The file cannot be read or is not a valid profile.
    """
    try:
        return DeviceProfile.load(path) if path else DeviceProfile.default()
    except DeviceError as exc:
        raise ParameterError(str(exc)) from exc
