"""Security headers on every HTTP response, and CORS for the configured origins only.

The dashboard is ES modules and a stylesheet from this origin, with no inline script or style
attribute, so its policy allows scripts, styles, fetches and websockets from ``'self'`` only, and
frames from ``'self'`` and the 3D view's port. ``/docs`` (Swagger UI) and ``/redoc`` load their
bundles from the gateway (``api_docs``) but run an inline script, and ReDoc sets inline styles and
starts a worker from a blob, so they get a policy of their own. No page may be framed by another site.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI
from starlette.middleware.cors import CORSMiddleware
from starlette.types import ASGIApp, Message, Receive, Scope, Send

DOCS_PATHS = ("/docs", "/redoc")
SAFE_HOST = re.compile(r"^[A-Za-z0-9.\-]+$|^\[[0-9A-Fa-f:.]+\]$")


def content_security_policy(path: str, frame_origin: str | None, style_hashes: Sequence[str] = ()) -> str:
    """The CSP for a response to ``path``; ``frame_origin`` is where the 3D view is served, if on;
    ``style_hashes`` ("sha256-...") are the inline stylesheets a page may have."""
    if path.startswith(DOCS_PATHS):
        return ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
                "img-src 'self' data:; worker-src 'self' blob:; frame-ancestors 'none'; object-src 'none'")
    frames = "'self'" + (f" {frame_origin}" if frame_origin else "")
    styles = "".join(f" '{h}'" for h in style_hashes)
    return (f"default-src 'self'; script-src 'self'; style-src 'self'{styles}; img-src 'self' data: blob:; "
            f"connect-src 'self'; frame-src {frames}; object-src 'none'; base-uri 'self'; form-action 'self'; "
            "frame-ancestors 'none'")


class SecurityHeaders:
    """ASGI middleware adding the security headers to every HTTP response (websockets pass)."""

    def __init__(self, app: ASGIApp, *, hsts: bool = False) -> None:
        self.app = app
        self.hsts = hsts

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        policy = content_security_policy(scope.get("path", ""), _frame_origin(scope))

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {name.lower() for name, _ in headers}
                for name, value in self._headers(policy):
                    if name not in present:
                        headers.append((name, value))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)

    def _headers(self, policy: str) -> list[tuple[bytes, bytes]]:
        headers = [
            (b"content-security-policy", policy.encode()),
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"no-referrer"),
            (b"x-frame-options", b"DENY"),
            (b"cross-origin-opener-policy", b"same-origin"),
        ]
        if self.hsts:
            headers.append((b"strict-transport-security", b"max-age=31536000"))
        return headers


def _frame_origin(scope: Scope) -> str | None:
    """The 3D view's origin as the dashboard will embed it: this request's host, its port."""
    app: Any = scope.get("app")
    port = getattr(getattr(app, "state", None), "view3d_port", None) if app is not None else None
    if port is None:
        return None
    host = ""
    for name, value in scope.get("headers", []):
        if name == b"host":
            host = value.decode("latin-1").rsplit(":", 1)[0] if not value.startswith(b"[") else value.decode("latin-1").split("]")[0] + "]"
            break
    if not SAFE_HOST.match(host or ""):
        return None
    scheme = "https" if scope.get("scheme") == "https" else "http"
    return f"{scheme}://{host}:{int(port)}"


def add_security_middleware(app: FastAPI, cors_origins: Sequence[str], *, hsts: bool) -> None:
    """Security headers on every response; CORS only for ``cors_origins`` (none: browsers keep
    other sites' pages from reading the API, the default)."""
    app.add_middleware(SecurityHeaders, hsts=hsts)
    if cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=list(cors_origins), allow_credentials=False,
                           allow_methods=["GET", "POST", "PUT", "DELETE"], allow_headers=["Authorization", "Content-Type"],
                           expose_headers=["X-Total-Count", "Retry-After"], max_age=600)
