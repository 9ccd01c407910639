"""The SDK2 port's certificate: made once in the user's data directory, for 127.0.0.1 and
localhost, its key readable by the user only, made anew when damaged; a real TLS handshake
checks it (Python's ssl, verifying against the certificate itself)."""

from __future__ import annotations

import asyncio
import ipaddress
import ssl
import stat
import sys
from pathlib import Path

import pytest
from cryptography import x509

from phantomtouch.bhaptics.sdk2.tls import CERT_NAME, KEY_NAME, data_dir, server_context


def test_the_pair_is_made_once_for_loopback_names(tmp_path: Path) -> None:
    folder = tmp_path / "phantomtouch"
    server_context(folder)
    key, cert = folder / KEY_NAME, folder / CERT_NAME
    first = cert.read_bytes()
    names = x509.load_pem_x509_certificate(first).extensions.get_extension_for_class(
        x509.SubjectAlternativeName
    )
    assert "localhost" in names.value.get_values_for_type(x509.DNSName)
    assert ipaddress.ip_address("127.0.0.1") in names.value.get_values_for_type(x509.IPAddress)
    if sys.platform != "win32":
        assert stat.S_IMODE(key.stat().st_mode) == 0o600
    server_context(folder)
    assert cert.read_bytes() == first, "a second start made a new certificate"


def test_a_damaged_pair_is_made_anew(tmp_path: Path) -> None:
    server_context(tmp_path)
    (tmp_path / KEY_NAME).write_text("not a key")
    server_context(tmp_path)
    assert b"PRIVATE KEY" in (tmp_path / KEY_NAME).read_bytes()


def test_the_data_directory_follows_xdg(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    if sys.platform != "win32":
        assert data_dir() == tmp_path / "phantomtouch"


def test_a_client_completes_a_handshake_for_127_0_0_1(tmp_path: Path) -> None:
    async def handshake() -> str:
        server = await asyncio.start_server(
            lambda r, w: w.close(), "127.0.0.1", 0, ssl=server_context(tmp_path)
        )
        port = server.sockets[0].getsockname()[1]
        client = ssl.create_default_context(cafile=tmp_path / CERT_NAME)
        _, writer = await asyncio.open_connection("127.0.0.1", port, ssl=client)
        version = writer.get_extra_info("ssl_object").version()
        writer.close()
        server.close()
        return str(version)

    assert asyncio.run(handshake()).startswith("TLSv1.")
