"""Memory a source's large messages took, given back to the system once the source goes.

A bHaptics game registers its ``.tact`` projects in messages of up to 16 MB; reading one
builds tens of megabytes of Python objects, freed when the connection closes. The C library
keeps freed memory for later in each thread's pool (glibc's arenas), so without a trim the
service stays as large as its largest moment. :func:`give_back_memory` asks glibc to return
what is free (``malloc_trim``); elsewhere (Windows, macOS, musl) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import sys
from collections.abc import Callable


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    if sys.platform != "linux":
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
    except OSError:
        return None
    trim: Callable[[int], int] | None = getattr(libc, "malloc_trim", None)
    return trim


def give_back_memory() -> bool:
    """Return the C library's free memory to the system; whether any was returned (host,
    any thread but the event loop: it may take some milliseconds)."""
    trim = _malloc_trim()
    return trim is not None and bool(trim(0))
