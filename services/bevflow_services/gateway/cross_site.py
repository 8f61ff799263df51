"""Requests another web site makes a browser send: refused when they would act with the user's rights.

A browser attaches the session cookie by itself, and with access control off every request is an
admin, so a page from another site could act on the gateway through the user's browser: a form
POST (cross-site request forgery), or a page whose own name is made to point at 127.0.0.1 (DNS
rebinding, where the browser believes it talks to that page's own site). Two rules:

- with access control off (``Access.loopback_only``), only requests naming this machine in their
  ``Host`` header (``localhost``, ``127.0.0.1``, ``[::1]``) are served;
- a request that changes something (POST, PUT, PATCH, DELETE) or opens a websocket, and whose
  rights come from the cookie or from access control being off rather than from an API token, must
  come from the gateway's own pages: its ``Origin`` header, which browsers send on such requests,
  must be the host it reached (``Sec-Fetch-Site`` must not say another site when no Origin is sent).

Programs with an API token (``Authorization: Bearer``, ``?token=`` on a websocket) carry no ambient
right and are not checked: what they may do comes from the token they chose to send.
"""

from __future__ import annotations

from starlette.datastructures import Headers, QueryParams
from starlette.requests import cookie_parser
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send
from starlette.websockets import WebSocket

from bevflow_services.gateway.auth import SESSION_COOKIE, Access, is_loopback

SAFE_METHODS = ("GET", "HEAD", "OPTIONS")


class CrossSiteGuard:
    """ASGI middleware refusing (403) what ``refusal`` names."""

    def __init__(self, app: ASGIApp, access: Access) -> None:
        self.app = app
        self.access = access

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        reason = refusal(scope, self.access) if scope["type"] in ("http", "websocket") else None
        if reason is None:
            await self.app(scope, receive, send)
        elif scope["type"] == "http":
            await JSONResponse({"detail": reason}, status_code=403)(scope, receive, send)
        else:
            await refuse_socket(WebSocket(scope, receive, send), reason)


async def refuse_socket(websocket: WebSocket, reason: str) -> None:
    """HTTP 403 to the handshake where the server can send one; else closed with 1008."""
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        await websocket.send_denial_response(JSONResponse({"detail": reason}, status_code=403))
    else:
        await websocket.close(code=1008, reason=reason[:120])


def refusal(scope: Scope, access: Access) -> str | None:
    """Why this request is refused, or None."""
    headers = Headers(scope=scope)
    host = headers.get("host", "")
    if access.loopback_only and not is_loopback(host_name(host)):
        return (f"Host {host!r} does not name this machine: with access control off the gateway answers "
                "only to localhost, 127.0.0.1 or [::1]")
    if scope["type"] == "http" and scope["method"] in SAFE_METHODS:
        return None
    if not ambient(scope, headers, access):
        return None
    origin = headers.get("origin")
    if origin is not None and origin.split("://", 1)[-1].rstrip("/") != host:
        return f"a request from {origin} may not act on this gateway with your login; use the gateway's own pages"
    if origin is None and headers.get("sec-fetch-site") in ("cross-site", "same-site"):
        return "a request from another site may not act on this gateway with your login"
    return None


def ambient(scope: Scope, headers: Headers, access: Access) -> bool:
    """Whether the request's rights would come without the page asking for them: the session
    cookie, or access control off (as ``Access.principal`` decides who is asking)."""
    if not access.enabled:
        return True
    scheme, _, credential = headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and credential.strip():
        return False
    if scope["type"] == "websocket" and QueryParams(scope.get("query_string", b"")).get("token"):
        return False
    return SESSION_COOKIE in cookie_parser(headers.get("cookie", ""))


def host_name(host: str) -> str:
    """``host`` without its port: ``[::1]:8000`` -> ``::1``, ``localhost:8000`` -> ``localhost``."""
    if host.startswith("["):
        return host[1:].split("]", 1)[0]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host
