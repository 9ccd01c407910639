"""JSON read in slices, so that one large message holds no other thread of the service.

A thread that parses JSON with :func:`json.loads` holds the interpreter for the whole
text: 11 MB of bHaptics submits take 0.2–0.7 s, in which neither the service's event loop
nor the contact lane nor the bHaptics stand-in's own loop runs, though the parse is in a
worker thread. :func:`read_json` parses a text longer than :data:`SLICE_BYTES` with
``ijson``'s compiled parser, fed one slice at a time by Python code, where a waiting
thread takes the interpreter (after ``sys.getswitchinterval()``, 5 ms); the text is read
whole, as one document, as :func:`json.loads` reads it (docs/security.md).

Taking the document apart builds as many objects again. While that many objects are
alive, each full pass of the cyclic garbage collector scans all of them, holding every
thread for up to 0.25 s at 11 MB; the document is a tree, with nothing for it to free.
:func:`collector_held` holds automatic collection off while a large message is read and
taken apart (for the process: the collector is one for every thread). What the message
leaves behind is scanned once when the hold ends, as anything new is (about 0.1 s for
7 MB kept); a refused message is let go of before (:func:`let_go`), leaving nothing.
"""

from __future__ import annotations

import gc
import json
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, ParamSpec, TypeVar

import ijson

P = ParamSpec("P")
T = TypeVar("T")

SLICE_BYTES = 64 << 10
"""Bytes parsed between two chances for another thread to run (about 2 ms of parsing);
a text up to this long is read by :func:`json.loads` at once."""
FREE_ITEMS = 1024
"""Items of a large array freed between two chances for another thread to run."""


class _Slices:
    """A file-like view of ``data`` whose :meth:`read` is Python code: each call is a point
    where the interpreter can pass to another thread."""

    def __init__(self, data: bytes) -> None:
        self._data = memoryview(data)
        self._at = 0

    def read(self, size: int) -> bytes:
        piece = self._data[self._at : self._at + size]
        self._at += len(piece)
        return bytes(piece)


def read_json(text: str) -> Any:
    """The one JSON value of ``text`` (any thread; pure).

    Parameters
    ----------
    text : str
        A JSON document. One longer than :data:`SLICE_BYTES` is read in slices; it must
        then be strict JSON (RFC 8259): ``NaN``, ``Infinity``, a number beyond a float's
        range, an integer beyond 64 bits and invalid UTF-8 are refused, and an escaped
        lone surrogate reads as ``?``, where :func:`json.loads` would take them.

    Raises
    ------
    ValueError
        ``text`` is not one JSON document.
    RecursionError
        A short ``text`` nests deeper than the interpreter's recursion limit.
    """
    if len(text) <= SLICE_BYTES:
        return json.loads(text)
    data = text.encode("utf-8", errors="surrogatepass")
    try:
        (document,) = ijson.items(_Slices(data), "", use_float=True, buf_size=SLICE_BYTES)
    except ijson.JSONError as exc:
        raise ValueError(str(exc).splitlines()[0]) from None
    return document


def let_go(items: list[Any]) -> None:
    """Empty ``items`` (a large array of a document) :data:`FREE_ITEMS` at a time: freeing
    11 MB of objects at once holds every thread for about 0.1 s."""
    while items:
        del items[-FREE_ITEMS:]


class _CollectorHold:
    """Who holds automatic collection off: it is off while any holds it, and on again
    after the last lets go if it was on before the first took it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._holders = 0
        self._was_enabled = False

    def take(self) -> None:
        with self._lock:
            if self._holders == 0:
                self._was_enabled = gc.isenabled()
                gc.disable()
            self._holders += 1

    def release(self) -> None:
        with self._lock:
            self._holders -= 1
            if self._holders == 0 and self._was_enabled:
                gc.enable()


_HOLD = _CollectorHold()


@contextmanager
def collector_held() -> Iterator[None]:
    """Automatic garbage collection off for the block (any thread; nests, across threads
    too). For reading a large message only: cyclic garbage made meanwhile by any thread
    waits for the next collection after it."""
    _HOLD.take()
    try:
        yield
    finally:
        _HOLD.release()


def without_collection(work: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """``work(*args, **kwargs)`` under :func:`collector_held`: for a worker thread that
    reads a large message (``loop.run_in_executor`` and ``asyncio.to_thread`` take it)."""
    with collector_held():
        return work(*args, **kwargs)
