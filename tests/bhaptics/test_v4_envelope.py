"""The v4 envelope (tact-js 2.x) against a second implementation of its client side.

tact-js 2.x itself is not to be had (the npm registry serves tact-js 0.0.8 only, a v2
client), so its side of the handshake is written from the description (docs/bhaptics.md,
"v4") with node's own crypto (``v4_client.mjs``) and run as a real node process: it reads
the server's ``ServerKey`` (DER SubjectPublicKeyInfo, base64), seals its AES-256 key with
RSA PKCS#1 v1.5 and a v3 message with AES-256-GCM (nonce first, tag last), and opens what
the server seals. Without node the test skips, naming the package; under CI=true it fails.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import padding

from phantomtouch.bhaptics.v4_envelope import (
    CLOSE_INVALID,
    CLOSE_OUT_OF_ORDER,
    EnvelopeError,
    ServerKey,
    State,
    V4Envelope,
)
from phantomtouch.errors import ProtocolError

CLIENT = Path(__file__).with_name("v4_client.mjs")
KEY = ServerKey()  # one RSA-2048 key for the module: making one takes 50-200 ms
PLAY = json.dumps(
    {
        "Type": "SdkPlay",
        "Message": json.dumps(
            {"eventName": "hit ✓", "requestId": 7, "intensity": 1.0, "duration": 1.0}
        ),
    }
)
READY = json.dumps({"Type": "ServerReady", "Message": ""})


def node(*args: str) -> str:
    program = shutil.which("node")
    if program is None:
        reason = "node is missing: scripts/install --dev installs the Debian package nodejs"
        if os.environ.get("CI") == "true":
            pytest.fail(f"{reason} (CI=true: the v4 interoperation test must run)")
        pytest.skip(reason)
    ran = subprocess.run([program, str(CLIENT), *args], capture_output=True, text=True, timeout=60)
    assert ran.returncode == 0, ran.stderr
    return ran.stdout


def handshake(envelope: V4Envelope, plaintext: str = PLAY) -> dict[str, Any]:
    client: dict[str, Any] = json.loads(node("hello", envelope.hello(), plaintext))
    return client


def test_a_client_of_another_implementation_talks_through_the_envelope() -> None:
    envelope = V4Envelope(KEY)
    hello = json.loads(envelope.hello())
    assert set(hello) == {"Type", "Key", "Data"}
    assert (hello["Type"], hello["Data"]) == ("ServerKey", None)
    client = handshake(envelope)
    assert client["rsaBits"] == 2048
    envelope.accept(client["clientKey"])
    assert envelope.state is State.OPEN
    assert envelope.open(client["data"]) == PLAY  # the client's v3 message, UTF-8 whole
    reply = envelope.seal(READY)
    sealed = json.loads(reply)
    assert (sealed["Type"], sealed["Key"]) == ("SdkData", None)
    assert node("open", client["aesKeyHex"], reply) == READY
    # a fresh nonce each time: the same plaintext never seals to the same bytes
    assert envelope.seal(READY) != reply


def test_the_public_key_is_the_der_subject_public_key_info_of_the_private_key() -> None:
    der = base64.b64decode(json.loads(V4Envelope(KEY).hello())["Key"])
    public = serialization.load_der_public_key(der)
    expected = KEY.private_key.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )
    assert (
        public.public_bytes(
            serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
        )
        == expected
    )


def client_key_of(secret: bytes) -> str:
    """An ``SdkClientKey`` sealing ``secret`` with the server's key, as a client seals it."""
    sealed = KEY.private_key.public_key().encrypt(secret, padding.PKCS1v15())
    return json.dumps({"Type": "SdkClientKey", "Key": base64.b64encode(sealed).decode()})


def refused(call: Any, close_code: int, words: str) -> None:
    with pytest.raises(EnvelopeError, match=words) as caught:
        call()
    assert caught.value.close_code == close_code
    assert isinstance(caught.value, ProtocolError)


def test_steps_out_of_order_are_refused_saying_what_was_expected() -> None:
    envelope = V4Envelope(KEY)
    data = json.dumps({"Type": "SdkData", "Key": None, "Data": "AAAA"})
    refused(lambda: envelope.open(data), CLOSE_OUT_OF_ORDER, "expected SdkClientKey, got 'SdkData'")
    refused(lambda: envelope.seal(READY), CLOSE_OUT_OF_ORDER, "expected SdkClientKey first")
    envelope.accept(client_key_of(os.urandom(32)))
    again = client_key_of(os.urandom(32))
    refused(
        lambda: envelope.accept(again), CLOSE_OUT_OF_ORDER, "expected SdkData, got 'SdkClientKey'"
    )
    refused(lambda: envelope.open({"type": "Other"}), CLOSE_OUT_OF_ORDER, "got 'Other'")


def test_what_does_not_read_or_decrypt_is_refused_as_invalid() -> None:
    fresh = V4Envelope(KEY)
    refused(lambda: fresh.accept("{nope"), CLOSE_INVALID, "not JSON")
    refused(lambda: fresh.accept("[1]"), CLOSE_INVALID, "got list")
    refused(lambda: fresh.accept({"Type": "SdkClientKey", "Key": 5}), CLOSE_INVALID, "base64 text")
    refused(
        lambda: fresh.accept({"Type": "SdkClientKey", "Key": "!!"}), CLOSE_INVALID, "not base64"
    )
    refused(
        lambda: fresh.accept(
            {"Type": "SdkClientKey", "Key": base64.b64encode(b"x" * 256).decode()}
        ),
        CLOSE_INVALID,
        "does not decrypt|AES-256 needs 32",  # OpenSSL may answer garbage with random bytes
    )
    refused(lambda: fresh.accept(client_key_of(b"k" * 16)), CLOSE_INVALID, "16-byte key")
    assert fresh.state is State.AWAITING_CLIENT_KEY
    envelope = V4Envelope(KEY)
    client = handshake(envelope)
    envelope.accept(client["clientKey"])
    message = json.loads(client["data"])
    altered = bytearray(base64.b64decode(message["Data"]))
    altered[20] ^= 1
    message["Data"] = base64.b64encode(bytes(altered)).decode()
    refused(lambda: envelope.open(message), CLOSE_INVALID, "does not decrypt")
    short = {"Type": "SdkData", "Data": base64.b64encode(b"x" * 27).decode()}
    refused(lambda: envelope.open(short), CLOSE_INVALID, "27 bytes; at least 28")
    other = V4Envelope(KEY)  # another connection's key cannot open this one's data
    other.accept(client_key_of(os.urandom(32)))
    refused(lambda: other.open(client["data"]), CLOSE_INVALID, "does not decrypt")
    assert envelope.open(client["data"]) == PLAY  # the envelope is still usable
