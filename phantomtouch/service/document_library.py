"""A library of JSON documents kept as they were given: ``.tact`` projects and SDK2 workspaces.

Each document is stored as compact JSON with its size and a summary beside it
(:mod:`phantomtouch.service.store_tables`), so that a listing never reads a document. A
:class:`DocumentLibrary` is one such table seen from a route or a command: list a page of
summaries, read a document back (404 naming the key when there is none), store one,
remove one. There are two: :data:`TACT` and :data:`WORKSPACES`; their parsers are
:mod:`~phantomtouch.service.tact_library` and :mod:`~phantomtouch.service.workspace_library`.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from pydantic import BaseModel, ValidationError

from phantomtouch.service.errors import NotFoundError
from phantomtouch.service.tact_models import TactInfo
from phantomtouch.service.workspace_models import WorkspaceInfo

if TYPE_CHECKING:
    from phantomtouch.service.store import PatternStore
    from phantomtouch.service.store_tables import SizedTable

logger = logging.getLogger("phantomtouch.server.store")

Info = TypeVar("Info", bound=BaseModel)


def document_value(document: bytes | str) -> Any:
    """The JSON value of a document's text (any thread; pure): bytes are read as UTF-8, a
    byte-order mark is dropped.

    Raises
    ------
    ValueError
        It is not JSON (the document's parser names the field at fault first).
    """
    text = (
        bytes(document).decode("utf-8-sig", errors="replace")
        if isinstance(document, bytes | bytearray)
        else document.removeprefix("\ufeff")
    )
    return json.loads(text)


def compact(value: Any) -> str:
    """A JSON value as the compact text the library stores (pure)."""
    return json.dumps(value, separators=(",", ":"), ensure_ascii=False)


@dataclass(frozen=True)
class DocumentLibrary(Generic[Info]):
    """One table of documents, by key (any thread: each call is one store transaction).

    Parameters
    ----------
    table : SizedTable
        The store's table.
    key : str
        What the key is called in requests and in ``info`` (``name``, ``workspace_id``).
    info : type of BaseModel
        What a listing answers per document: the summary's fields, ``key`` and ``bytes``.
    where : str
        Where a missing document is not, for the 404 (``in the .tact library (GET /tact)``).
    log_name : str
        The document's name in log lines (``tact``, ``workspace``).
    """

    table: SizedTable
    key: str
    info: type[Info]
    where: str
    log_name: str

    def listed(self, store: PatternStore, *, limit: int, offset: int) -> list[Info]:
        """One page of the stored documents' summaries, sorted by key; a row whose summary
        no longer reads is logged and left out."""
        page = []
        for key, size, stored in store.list_documents(self.table, limit, offset):
            try:
                page.append(self.info.model_validate({**json.loads(stored), **self._id(key, size)}))
            except (ValueError, ValidationError) as exc:
                logger.warning(
                    "%s=%r: its stored summary no longer reads (%s); left out",
                    self.log_name,
                    key,
                    exc,
                )
        return page

    def text(self, store: PatternStore, key: str, *, field: str | None = None) -> str:
        """The document stored as ``key``, as stored.

        Raises
        ------
        NotFoundError
            None is stored as ``key``; ``field`` is what the request called it (default
            :attr:`key`).
        """
        text = store.get_document(self.table, key)
        if text is None:
            raise self.not_found(key, field=field)
        return text

    def put(self, store: PatternStore, key: str, text: str, summary: dict[str, Any]) -> Info:
        """Store (or replace) the document ``text`` as ``key`` with its summary; its
        listing entry."""
        store.put_document(self.table, key, text, summary)
        return self.info.model_validate({**summary, **self._id(key, len(text.encode("utf-8")))})

    def delete(self, store: PatternStore, key: str) -> None:
        """Remove the document ``key``.

        Raises
        ------
        NotFoundError
            None is stored as ``key``.
        """
        if not store.delete_document(self.table, key):
            raise self.not_found(key)

    def not_found(self, key: str, *, field: str | None = None) -> NotFoundError:
        """The 404 of a key that is not stored (``field``: default :attr:`key`)."""
        field = field or self.key
        return NotFoundError(f"{field}={key!r} is not {self.where}", field=field, value=key)

    def _id(self, key: str, size_bytes: int) -> dict[str, Any]:
        return {self.key: key, "bytes": size_bytes}


TACT = DocumentLibrary("tact", "name", TactInfo, "in the .tact library (GET /tact)", "tact")
"""The stored ``.tact`` projects (``/tact/{name}``, ``phantomtouch import``)."""
WORKSPACES = DocumentLibrary(
    "workspaces",
    "workspace_id",
    WorkspaceInfo,
    "in the workspace library (GET /bhaptics/workspaces)",
    "workspace",
)
"""The stored deployments by workspace id (``/bhaptics/workspaces/{id}``, ``phantomtouch
import``)."""
