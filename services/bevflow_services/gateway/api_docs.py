"""``/docs`` (Swagger UI) and ``/redoc`` with every asset served by the gateway itself.

FastAPI's own pages load their scripts and styles from a CDN, so on a site without internet (most
control rooms) they stay blank. The ``fastapi-offline`` package ships the Swagger UI and ReDoc
bundles (MIT licensed, like the projects they come from); the gateway serves them under
``/docs-assets`` and builds the two pages around them, with no Google fonts.
"""

from __future__ import annotations

from importlib.resources import files

from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

ASSETS = "/docs-assets"


def add_api_docs(app: FastAPI, title: str) -> None:
    """Serve ``/docs`` and ``/redoc`` from local assets; ``app`` must be built with
    ``docs_url=None, redoc_url=None``."""
    static = files("fastapi_offline") / "static"
    app.mount(ASSETS, StaticFiles(directory=str(static)), name="docs-assets")
    spec = app.openapi_url or "/openapi.json"

    @app.get("/docs", include_in_schema=False)
    def swagger() -> HTMLResponse:
        return get_swagger_ui_html(openapi_url=spec, title=f"{title}: API", swagger_js_url=f"{ASSETS}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{ASSETS}/swagger-ui.css", swagger_favicon_url=f"{ASSETS}/favicon.png")

    @app.get("/redoc", include_in_schema=False)
    def redoc() -> HTMLResponse:
        return get_redoc_html(openapi_url=spec, title=f"{title}: API", redoc_js_url=f"{ASSETS}/redoc.standalone.js",
                              redoc_favicon_url=f"{ASSETS}/favicon.png", with_google_fonts=False)
