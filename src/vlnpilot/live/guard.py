"""What the live station checks before its app sees a request: the Host, the Origin, the token, the body's size.

- Host: on a loopback address only loopback names are answered (localhost, 127.x.x.x, [::1]); a page that a
  rebinding DNS name points at 127.0.0.1 sends its own name and gets 421. Off loopback the bound address is
  answered (any name when bound to all interfaces, where a token is required anyway).
- Origin: a request that carries one (every browser POST does) must come from the station's own page; 403.
- Token: a POST needs `Authorization: Bearer <token>` when the station has one (401), checked before its body
  is read, so an anonymous client cannot make the station read, parse or echo anything.
- Body: at most MAX_BODY_BYTES (413): a control message is a few dozen bytes.
"""

from __future__ import annotations

import hmac
import json
from typing import Any
from urllib.parse import urlsplit

from vlnpilot.server.app import BodyLimitMiddleware, is_loopback

MAX_BODY_BYTES = 4096
WILDCARDS = ("0.0.0.0", "::", "")
LOOPBACK_NAMES = ("localhost",)


class StationGuard:
    """ASGI middleware in front of the live app (see the module's docstring)."""

    def __init__(self, app: Any, *, host: str, token: str | None, max_body_bytes: int = MAX_BODY_BYTES):
        self.app = BodyLimitMiddleware(app, max_bytes=max_body_bytes)
        self.host, self.token = host.strip("[]").lower(), token

    def host_allowed(self, name: str) -> bool:
        name = name.strip("[]").lower()
        if is_loopback(self.host):
            return name in LOOPBACK_NAMES or is_loopback(name)
        return self.host in WILDCARDS or name == self.host

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", ())}
        host = headers.get("host", "")
        name = urlsplit(f"//{host}").hostname or ""
        if not self.host_allowed(name):
            await _refuse(send, 421, f"this station does not answer for host {host[:80]!r}")
            return
        origin = headers.get("origin")
        if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
            await _refuse(send, 403, f"requests from {origin[:80]!r} are refused: only the station's own page")
            return
        if scope.get("method") == "POST" and self.token is not None and not token_ok(headers.get("authorization"),
                                                                                     self.token):
            await _refuse(send, 401, "missing or wrong token (Authorization: Bearer ...)")
            return
        await self.app(scope, receive, send)


def token_ok(authorization: str | None, token: str) -> bool:
    scheme, _, given = (authorization or "").partition(" ")
    return scheme.lower() == "bearer" and hmac.compare_digest(given.strip().encode(), token.encode())


async def _refuse(send: Any, status: int, error: str) -> None:
    body = json.dumps({"error": error}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})
