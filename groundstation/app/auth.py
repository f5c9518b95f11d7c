"""One access token per server run, as Jupyter does. The URL printed at start carries it
(``?token=...``); the first request that shows it gets an HttpOnly cookie, so the page, its
API calls, the viser view and the websockets all carry it from then on. Other tools may send
``Authorization: Bearer <token>``. Everything is refused without it (401, or websocket close
1008), unless the server was started with ``--no-auth`` on a loopback address."""

from __future__ import annotations

import hmac
import ipaddress
import secrets
from http.cookies import SimpleCookie
from urllib.parse import parse_qs

COOKIE = "peregrine_token"


def new_token() -> str:
    return secrets.token_urlsafe(24)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _headers(scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def presented_token(scope) -> tuple[str | None, bool]:
    """The token a request carries, and whether it came in the query string."""
    query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
    if "token" in query:
        return query["token"][0], True
    headers = _headers(scope)
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip(), False
    cookie = SimpleCookie()
    try:
        cookie.load(headers.get("cookie", ""))
    except Exception:
        return None, False
    if COOKIE in cookie:
        return cookie[COOKIE].value, False
    return None, False


class TokenAuthMiddleware:
    """Pure ASGI middleware: checks HTTP requests and websocket handshakes alike."""

    def __init__(self, app, token: str | None) -> None:
        self.app = app
        self.token = token

    def _ok(self, presented: str | None) -> bool:
        return presented is not None and hmac.compare_digest(presented, self.token)

    async def __call__(self, scope, receive, send):
        if self.token is None or scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        presented, from_query = presented_token(scope)
        if not self._ok(presented):
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 1008})
                return
            body = (
                b"<!doctype html><title>Peregrine</title><p>Access token required: open the "
                b"URL that <code>groundstation serve</code> printed.</p>"
            )
            await send(
                {
                    "type": "http.response.start",
                    "status": 401,
                    "headers": [
                        (b"content-type", b"text/html; charset=utf-8"),
                        (b"content-length", str(len(body)).encode()),
                    ],
                }
            )
            await send({"type": "http.response.body", "body": body})
            return
        if scope["type"] == "http" and from_query:
            cookie = (f"{COOKIE}={self.token}; HttpOnly; SameSite=Strict; Path=/").encode()

            async def send_with_cookie(message):
                if message["type"] == "http.response.start":
                    message = {
                        **message,
                        "headers": [*message.get("headers", []), (b"set-cookie", cookie)],
                    }
                await send(message)

            return await self.app(scope, receive, send_with_cookie)
        return await self.app(scope, receive, send)
