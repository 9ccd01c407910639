"""The SDK2 port's TLS certificate: self-signed for 127.0.0.1 and localhost, made once.

SDK2 clients connect to ``wss://127.0.0.1:15882`` and accept any certificate, so the
service makes its own the first time it serves SDK2 (an EC P-256 key and a certificate for
``127.0.0.1``, ``::1`` and ``localhost``, valid ten years, made with ``cryptography``) and
keeps both in the user's data directory (:func:`data_dir`), ``bhaptics-sdk2.key`` and
``bhaptics-sdk2.crt``. The key file is created readable and writable by its user only
(mode 0600 on Linux and macOS; on Windows the per-user ``%LOCALAPPDATA%`` folder is the
user's alone). A pair that does not load (damaged, half written) is made anew.

Host, the event loop's thread at start-up (a few ms for a new key).
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import ssl
import sys
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from phantomtouch.errors import DeviceError

KEY_NAME = "bhaptics-sdk2.key"
CERT_NAME = "bhaptics-sdk2.crt"
VALID_DAYS = 3650
"""How long a certificate made here is valid."""


def data_dir() -> Path:
    """The user's data directory of phantomtouch: ``%LOCALAPPDATA%\\phantomtouch`` on
    Windows, else ``$XDG_DATA_HOME/phantomtouch`` (``~/.local/share/phantomtouch``)."""
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "phantomtouch"
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "phantomtouch"


def make_pair(directory: Path) -> tuple[Path, Path]:
    """Write a new key and self-signed certificate into ``directory`` (made if missing);
    returns their paths (key, certificate).

    Raises
    ------
    DeviceError
        The directory or a file cannot be written.
    """
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "localhost")])
    now = datetime.datetime.now(datetime.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(days=1))
        .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
        .add_extension(
            x509.SubjectAlternativeName(
                [
                    x509.DNSName("localhost"),
                    x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
                    x509.IPAddress(ipaddress.ip_address("::1")),
                ]
            ),
            critical=False,
        )
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .sign(key, hashes.SHA256())
    )
    key_path, cert_path = directory / KEY_NAME, directory / CERT_NAME
    key_bytes = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    try:
        directory.mkdir(parents=True, exist_ok=True)
        key_path.unlink(missing_ok=True)
        descriptor = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(descriptor, "wb") as file:
            file.write(key_bytes)
        cert_path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    except OSError as exc:
        raise DeviceError(
            f"bhaptics-sdk2: cannot write its TLS key and certificate in {directory} "
            f"({exc.strerror})"
        ) from exc
    return key_path, cert_path


def server_context(directory: Path | None = None) -> ssl.SSLContext:
    """A server TLS context with the pair in ``directory`` (None: :func:`data_dir`), made
    there first if it is missing or does not load.

    Raises
    ------
    DeviceError
        No pair can be written or loaded.
    """
    directory = data_dir() if directory is None else directory
    key_path, cert_path = directory / KEY_NAME, directory / CERT_NAME
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        context.load_cert_chain(cert_path, key_path)
    except (OSError, ssl.SSLError):
        key_path, cert_path = make_pair(directory)
        try:
            context.load_cert_chain(cert_path, key_path)
        except (OSError, ssl.SSLError) as exc:
            raise DeviceError(
                f"bhaptics-sdk2: the TLS key and certificate made in {directory} do not load "
                f"({exc})"
            ) from exc
    return context
