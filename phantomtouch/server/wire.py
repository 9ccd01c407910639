"""uvicorn's HTTP protocol with the service's error body for requests it cannot parse.

A request uvicorn cannot parse (malformed framing, a request line or a header too long
for its parser) never reaches the app: uvicorn answers it itself, by default with a
plain-text ``400``. :class:`JsonErrorProtocol` answers the same ``400`` with the body of
every other refusal, ``{"error": {"code": "invalid", "message", "fields"}}``.
"""

from __future__ import annotations

import json

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from phantomtouch.server.errors import Problem


def malformed_body(reason: str) -> bytes:
    """The JSON error body of a request that could not be parsed."""
    message = f"malformed HTTP request: {reason}"
    field = {"field": "request", "value": None, "message": message}
    return json.dumps(Problem(400, "invalid", message, [field]).body()).encode()


class JsonErrorProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol whose parse errors answer the service's error body."""

    def send_400_response(self, msg: str) -> None:
        body = malformed_body(msg.rstrip(".").lower())
        content = [b"HTTP/1.1 400 Bad Request\r\n"]
        for name, value in self.server_state.default_headers:
            content.extend([name, b": ", value, b"\r\n"])
        content.extend(
            [
                b"content-type: application/json\r\n",
                b"content-length: " + str(len(body)).encode("ascii") + b"\r\n",
                b"connection: close\r\n",
                b"\r\n",
                body,
            ]
        )
        self.transport.write(b"".join(content))
        self.transport.close()
