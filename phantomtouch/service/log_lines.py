"""Log lines that tell the truth: no secret in them, and one line per record.

Every handler of an HTTP server of the project (:func:`~phantomtouch.service.listen.log_config`)
passes each record through :class:`SafeLines` before it is written:

- secrets are redacted: the value of a ``token``, ``password`` or ``secret`` query
  parameter (uvicorn logs a WebSocket's path with its query, ``/ws?token=...``) and of a
  ``Bearer`` credential become ``***``;
- every control character (CR, LF, the other C0 and C1 controls, U+2028 and U+2029) in
  the message, arguments included, is written as an escape (``\\r``, ``\\n``,
  ``\\x1b``, ``\\u2028``): a value from a request (a refused path, a header) cannot
  end the line and write one of its own. A traceback (``exc_info``) is the formatter's
  and keeps its lines.

The filter runs on the thread that logs.
"""

from __future__ import annotations

import logging
import re

REDACTED = "***"
_SECRET_PARAMETER = re.compile(r"(?i)([?&;](?:token|access_token|password|secret)=)[^&;#\s\"']*")
_BEARER = re.compile(r"(?i)(bearer\s+)[^\s\"',;]+")
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_ESCAPES = {"\r": "\\r", "\n": "\\n", "\t": "\\t"}


def _escape(match: re.Match[str]) -> str:
    char = match.group()
    if char in _ESCAPES:
        return _ESCAPES[char]
    code = ord(char)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def safe_line(text: str) -> str:
    """``text`` with its secrets redacted and its control characters escaped."""
    text = _SECRET_PARAMETER.sub(rf"\g<1>{REDACTED}", text)
    text = _BEARER.sub(rf"\g<1>{REDACTED}", text)
    return _CONTROL.sub(_escape, text)


class SafeLines(logging.Filter):
    """Rewrites each record's message as :func:`safe_line` of it (module docstring)."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except (TypeError, ValueError):
            message = f"{record.msg!r} % {record.args!r}"
        record.msg = safe_line(message)
        record.args = None
        return True
