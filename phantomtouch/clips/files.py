"""Reading a clip file from disk, the same way for every kind (``.haptic``, ``.ahap``,
``.tact``, a deployment): its size is checked before it is read, and a file that cannot be
read is the kind's own error, naming the file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from phantomtouch.errors import ParameterError


def read_limited(
    path: Path,
    *,
    max_bytes: int,
    what: str,
    error: Callable[[str], ParameterError] = ParameterError,
) -> bytes:
    """The bytes of the file at ``path`` (the caller's thread: file I/O).

    Parameters
    ----------
    path : Path
    max_bytes : int, > 0
        A larger file is refused before it is read.
    what : str
        What the file is, in the message of a refusal (``a clip file``, ``a deployment``).
    error : callable (message) -> ParameterError
        The kind's error (default :class:`~phantomtouch.errors.ParameterError`).

    Raises
    ------
    ParameterError
        ``error`` of a file larger than ``max_bytes``, or one that cannot be read.
    """
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise error(f"{path}: {size} bytes; {what} may have {max_bytes}")
        return path.read_bytes()
    except OSError as exc:
        raise error(f"cannot read {str(path)!r}: {exc.strerror or exc}") from exc
