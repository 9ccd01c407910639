"""bHaptics SDK2 "v4" (tact-js 2.x, web games): the handshake and the encrypted envelope.

A web game connects to ``ws://127.0.0.1:15881/v4/feedback?workspace_id=&api_key=&version=``
(the SDK1 port, no TLS) and speaks the v3 messages (``{"Type": "Sdk...", "Message": ...}``
and the ``Server...`` answers) inside an envelope (docs/bhaptics.md, "v4")::

    server  {"Type": "ServerKey", "Key": base64(DER SubjectPublicKeyInfo of RSA-2048),
             "Data": null}
    client  {"Type": "SdkClientKey", "Key": base64(RSA PKCS#1 v1.5 encryption of its random
             32-byte AES key)}
    both    {"Type": "SdkData", "Key": null, "Data": base64(nonce[12] || AES-256-GCM
             ciphertext || tag[16])}          (no associated data; the plaintext: UTF-8 text
                                                of one v3 message)

:class:`V4Envelope` is one connection's side of it, a state machine: :meth:`~V4Envelope.hello`
(the ``ServerKey`` to send on connect), :meth:`~V4Envelope.accept` (the client's
``SdkClientKey``; then the envelope is open), :meth:`~V4Envelope.seal` and
:meth:`~V4Envelope.open` (each ``SdkData`` out and in). Every illegal step or unreadable
message is a :class:`~phantomtouch.errors.ProtocolError` saying what was expected and what
came (close 1008 for a step out of order, 1007 for data that does not decrypt, as
:data:`CLOSE_OUT_OF_ORDER` and :data:`CLOSE_INVALID` name them). :class:`ServerKey` is the
RSA key pair; one serves every connection of a listener (making one takes 50-200 ms).

Pure: no I/O, no clock; randomness from the operating system (``os.urandom``). Every method
runs in the caller's thread; one envelope is used by one task at a time.
"""

from __future__ import annotations

import base64
import binascii
import enum
import json
import os
from collections.abc import Mapping
from typing import Any

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import padding, rsa
from cryptography.hazmat.primitives.ciphers.aead import AESGCM

from phantomtouch.errors import ProtocolError

RSA_BITS = 2048
"""The server key's size, bits (tact-js 2.x expects RSA-2048)."""
AES_KEY_BYTES = 32
"""The client's AES-256 key, bytes."""
NONCE_BYTES = 12
"""AES-GCM nonce, bytes, sent first in each ``Data``."""
TAG_BYTES = 16
"""AES-GCM tag, bytes, sent last in each ``Data``."""
MAX_DATA_CHARS = 16 << 20
"""Longest ``Data`` or ``Key`` text read, characters (a v3 message may carry a deployment)."""
CLOSE_OUT_OF_ORDER = 1008
"""WebSocket close code for a step out of order (policy violation)."""
CLOSE_INVALID = 1007
"""WebSocket close code for an envelope that does not read or decrypt (invalid payload)."""


class EnvelopeError(ProtocolError):
    """A v4 step out of order or an envelope that does not read; ``close_code`` is the
    WebSocket close code that answers it."""

    def __init__(self, message: str, *, close_code: int) -> None:
        super().__init__(message)
        self.close_code = close_code


class State(enum.Enum):
    """Where a connection's envelope stands."""

    AWAITING_CLIENT_KEY = "awaiting SdkClientKey"
    OPEN = "open"


class ServerKey:
    """The server's RSA key pair (any thread; immutable once made).

    Parameters
    ----------
    private_key : RSAPrivateKey or None
        None: a new RSA-2048 key (50-200 ms of CPU: make it outside the event loop).
    """

    def __init__(self, private_key: rsa.RSAPrivateKey | None = None) -> None:
        self.private_key = private_key or rsa.generate_private_key(65537, RSA_BITS)
        der = self.private_key.public_key().public_bytes(
            serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
        )
        self.public_key_b64 = base64.b64encode(der).decode("ascii")
        """The public key as ``ServerKey`` carries it: base64 of its DER SubjectPublicKeyInfo."""


class V4Envelope:
    """One connection's side of the v4 envelope (see the module's docstring).

    Parameters
    ----------
    key : ServerKey
        The listener's key pair.
    """

    def __init__(self, key: ServerKey) -> None:
        self.key = key
        self.state = State.AWAITING_CLIENT_KEY
        self._aes: AESGCM | None = None

    def hello(self) -> str:
        """The ``ServerKey`` message, the server's first (text of a JSON object)."""
        return json.dumps({"Type": "ServerKey", "Key": self.key.public_key_b64, "Data": None})

    def accept(self, message: str | bytes | Mapping[str, Any]) -> None:
        """Take the client's ``SdkClientKey``: decrypt its AES key; the envelope is open.

        Raises
        ------
        EnvelopeError
            Not awaiting it, or not ``{"Type": "SdkClientKey", "Key": base64}`` of an RSA
            encryption of :data:`AES_KEY_BYTES` bytes (the message says what came; a
            ``Key`` that is no such encryption may decrypt to random bytes, OpenSSL's
            implicit rejection, and is refused for their length).
        """
        fields = self._envelope(message, "SdkClientKey", State.AWAITING_CLIENT_KEY)
        sealed = _base64(fields.get("Key"), "Key")
        try:
            aes_key = self.key.private_key.decrypt(sealed, padding.PKCS1v15())
        except ValueError:
            raise EnvelopeError(
                "SdkClientKey.Key does not decrypt with the server key (RSA PKCS#1 v1.5)",
                close_code=CLOSE_INVALID,
            ) from None
        if len(aes_key) != AES_KEY_BYTES:
            raise EnvelopeError(
                f"SdkClientKey.Key holds a {len(aes_key)}-byte key; AES-256 needs {AES_KEY_BYTES}",
                close_code=CLOSE_INVALID,
            )
        self._aes = AESGCM(aes_key)
        self.state = State.OPEN

    def seal(self, plaintext: str) -> str:
        """``plaintext`` (a v3 message's text) as an ``SdkData`` message, a fresh nonce each.

        Raises
        ------
        EnvelopeError
            The envelope is not open yet (no ``SdkClientKey`` accepted).
        """
        aes = self._open_aes("seal")
        nonce = os.urandom(NONCE_BYTES)
        sealed = nonce + aes.encrypt(nonce, plaintext.encode("utf-8"), None)
        data = base64.b64encode(sealed).decode("ascii")
        return json.dumps({"Type": "SdkData", "Key": None, "Data": data})

    def open(self, message: str | bytes | Mapping[str, Any]) -> str:
        """The plaintext (a v3 message's text) of an ``SdkData`` message.

        Raises
        ------
        EnvelopeError
            The envelope is not open, the message is not ``SdkData`` with base64 ``Data``
            of at least nonce and tag, it does not decrypt (another key, altered), or the
            plaintext is not UTF-8.
        """
        fields = self._envelope(message, "SdkData", State.OPEN)
        sealed = _base64(fields.get("Data"), "Data")
        if len(sealed) < NONCE_BYTES + TAG_BYTES:
            raise EnvelopeError(
                f"SdkData.Data holds {len(sealed)} bytes; at least {NONCE_BYTES + TAG_BYTES} "
                "(nonce and tag)",
                close_code=CLOSE_INVALID,
            )
        aes = self._open_aes("open")
        try:
            plain = aes.decrypt(sealed[:NONCE_BYTES], sealed[NONCE_BYTES:], None)
        except InvalidTag:
            raise EnvelopeError(
                "SdkData.Data does not decrypt with this connection's key (AES-GCM tag)",
                close_code=CLOSE_INVALID,
            ) from None
        try:
            return plain.decode("utf-8")
        except UnicodeDecodeError:
            raise EnvelopeError(
                "SdkData.Data's plaintext is not UTF-8 text", close_code=CLOSE_INVALID
            ) from None

    def _open_aes(self, step: str) -> AESGCM:
        if self._aes is None:
            raise EnvelopeError(
                f"cannot {step} SdkData: expected SdkClientKey first, the envelope is "
                f"{self.state.value}",
                close_code=CLOSE_OUT_OF_ORDER,
            )
        return self._aes

    def _envelope(
        self, message: str | bytes | Mapping[str, Any], kind: str, state: State
    ) -> Mapping[str, Any]:
        """``message`` as an object of ``Type`` ``kind``, arriving in ``state``."""
        if isinstance(message, str | bytes | bytearray):
            if len(message) > MAX_DATA_CHARS + 1024:
                raise EnvelopeError(
                    f"a v4 message of {len(message)} characters; at most {MAX_DATA_CHARS}",
                    close_code=CLOSE_INVALID,
                )
            try:
                message = json.loads(message)
            except (ValueError, RecursionError):
                raise EnvelopeError(
                    f"expected {kind} as a JSON object, got text that is not JSON",
                    close_code=CLOSE_INVALID,
                ) from None
        if not isinstance(message, Mapping):
            raise EnvelopeError(
                f"expected {kind} as a JSON object, got {type(message).__name__}",
                close_code=CLOSE_INVALID,
            )
        fields = {str(k).lower(): v for k, v in message.items()}
        got = fields.get("type")
        if got != kind or self.state is not state:
            raise EnvelopeError(
                f"expected {_expected(self.state)}, got {got!r}", close_code=CLOSE_OUT_OF_ORDER
            )
        return {"Key": fields.get("key"), "Data": fields.get("data")}


def _expected(state: State) -> str:
    return "SdkClientKey" if state is State.AWAITING_CLIENT_KEY else "SdkData"


def _base64(value: object, field: str) -> bytes:
    if not isinstance(value, str) or len(value) > MAX_DATA_CHARS:
        shown = type(value).__name__ if not isinstance(value, str) else f"{len(value)} chars"
        raise EnvelopeError(
            f"{field} must be base64 text of at most {MAX_DATA_CHARS} characters, got {shown}",
            close_code=CLOSE_INVALID,
        )
    try:
        return base64.b64decode(value, validate=True)
    except (binascii.Error, ValueError):
        raise EnvelopeError(f"{field} is not base64", close_code=CLOSE_INVALID) from None
