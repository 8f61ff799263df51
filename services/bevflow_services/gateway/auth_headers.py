"""Security headers on every HTTP response, and CORS for the configured origins only.

The dashboard is ES modules and a stylesheet from this origin, with no inline script or style
attribute, so its policy allows scripts, styles, fetches, websockets and frames from ``'self'``
only. ``/docs`` (Swagger UI) and ``/redoc`` load their bundles from the gateway (``api_docs``) but
run an inline script, and ReDoc sets inline styles and starts a worker from a blob, so they get a
policy of their own. So does the 3D view (``/view3d/``, viser's page relayed from loopback), a
single file that unpacks its scripts and WebAssembly at run time; the dashboard frames it, so it may
be framed by the gateway's own pages. No page may be framed by another site.
"""

from __future__ import annotations

from collections.abc import Sequence

from fastapi import FastAPI
from starlette.middleware.cors import CORSMiddleware
from starlette.types import ASGIApp, Message, Receive, Scope, Send

DOCS_PATHS = ("/docs", "/redoc")
VIEW3D_PATH = "/view3d/"


def content_security_policy(path: str, style_hashes: Sequence[str] = ()) -> str:
    """The CSP for a response to ``path``; ``style_hashes`` ("sha256-...") are the inline
    stylesheets a page may have."""
    if path.startswith(DOCS_PATHS):
        return ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
                "img-src 'self' data:; worker-src 'self' blob:; frame-ancestors 'none'; object-src 'none'")
    if path.startswith(VIEW3D_PATH):
        return ("default-src 'self'; script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval' blob: data:; "
                "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
                "connect-src 'self' data: blob:; worker-src 'self' blob: data:; object-src 'none'; frame-ancestors 'self'")
    styles = "".join(f" '{h}'" for h in style_hashes)
    return (f"default-src 'self'; script-src 'self'; style-src 'self'{styles}; img-src 'self' data: blob:; "
            "connect-src 'self'; frame-src 'self'; object-src 'none'; base-uri 'self'; form-action 'self'; "
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
        path = scope.get("path", "")
        policy, framing = content_security_policy(path), b"SAMEORIGIN" if path.startswith(VIEW3D_PATH) else b"DENY"

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {name.lower() for name, _ in headers}
                for name, value in self._headers(policy, framing):
                    if name not in present:
                        headers.append((name, value))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)

    def _headers(self, policy: str, framing: bytes) -> list[tuple[bytes, bytes]]:
        headers = [
            (b"content-security-policy", policy.encode()),
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"no-referrer"),
            (b"x-frame-options", framing),
            (b"cross-origin-opener-policy", b"same-origin"),
        ]
        if self.hsts:
            headers.append((b"strict-transport-security", b"max-age=31536000"))
        return headers


def add_security_middleware(app: FastAPI, cors_origins: Sequence[str], *, hsts: bool) -> None:
    """Security headers on every response; CORS only for ``cors_origins`` (none: browsers keep
    other sites' pages from reading the API, the default)."""
    app.add_middleware(SecurityHeaders, hsts=hsts)
    if cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=list(cors_origins), allow_credentials=False,
                           allow_methods=["GET", "POST", "PUT", "DELETE"], allow_headers=["Authorization", "Content-Type"],
                           expose_headers=["X-Total-Count", "Retry-After"], max_age=600)
