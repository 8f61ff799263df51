"""The dashboard's files: its pages behind the login, and an allow-list of what anyone may fetch.

A request path is normalised first (``/./index.html``, ``//index.html`` and ``/index.html/`` all
name ``index.html``), so that no spelling of a page reaches it without the page's role. Anyone may
fetch the login page and the scripts, styles and images, which hold no data; nothing else in the
folder is served (``__init__.py``, hidden files), and no path leaves it.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response

from bevflow_services.gateway.auth import get_access

# The pages and the role each needs ("" is the folder's index, served at "/").
PAGES = {"index.html": "viewer", "calibration.html": "admin"}
PUBLIC_PAGES = ("login.html",)
PUBLIC_SUFFIXES = (".js", ".css", ".svg", ".png", ".ico")

PLACEHOLDER = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>bevflow</title></head>
<body style="font-family: sans-serif; margin: 2em">
<h1>bevflow gateway</h1>
<p>The dashboard is not installed here. The API is running:</p>
<ul>
<li><a href="/api/occupancy">/api/occupancy</a>, <a href="/api/health">/api/health</a>,
<a href="/api/cameras">/api/cameras</a>, <a href="/api/site">/api/site</a></li>
<li><a href="/docs">/docs</a>: every route, with its parameters</li>
</ul>
</body></html>
"""

FORBIDDEN = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>bevflow: not allowed</title>
<link rel="stylesheet" href="/style.css"><link rel="stylesheet" href="/css/login.css"></head>
<body><main class="login-page"><h1>Not allowed</h1>
<p>This page needs the {role} role; {name} is a {user_role}.</p>
<p><a href="/">Dashboard</a> · <a href="/logout">Log in as someone else</a></p></main></body></html>
"""


def normalised(path: str) -> str | None:
    """The file ``path`` names inside the folder ("" for the folder itself); None for a path that
    climbs out of it or names a hidden or private file (``..``, ``.git``, ``__init__.py``).

    >>> [normalised(p) for p in ("/", "/./index.html", "//index.html", "/js/../index.html/", "/__init__.py")]
    ['', 'index.html', 'index.html', None, None]
    """
    parts = [part for part in path.split("/") if part not in ("", ".")]
    if any(part.startswith((".", "_")) or "\\" in part for part in parts):
        return None
    return "/".join(parts)


def is_public(name: str) -> bool:
    return name in PUBLIC_PAGES or name.endswith(PUBLIC_SUFFIXES)


def serve_dashboard(app: FastAPI, folder: Path) -> None:
    """Answer every GET no other route claimed from ``folder`` (add it last)."""

    def dashboard(request: Request, path: str) -> Response:
        name = normalised(request.scope["path"])
        if name is None:
            raise HTTPException(404, "Not Found")
        if name in ("", *PAGES):
            return page_response(request, folder, name or "index.html")
        file = folder / name
        if not is_public(name) or not file.is_file():
            raise HTTPException(404, "Not Found")
        return FileResponse(file)

    app.add_api_route("/{path:path}", dashboard, methods=["GET", "HEAD"], include_in_schema=False)


def page_response(request: Request, folder: Path, name: str) -> Response:
    """A dashboard page for a user with its role; the login page for anyone else."""
    principal = get_access(request).principal(request)
    role = PAGES[name]
    if principal is None:
        target = "/" if name == "index.html" else f"/{name}"
        return RedirectResponse(f"/login.html?next={target}", status_code=303)
    if not principal.can(role):
        return HTMLResponse(FORBIDDEN.format(role=role, name=principal.name, user_role=principal.role), status_code=403)
    page = folder / name
    if page.is_file():
        return FileResponse(page, headers={"Cache-Control": "no-store"})
    return HTMLResponse(PLACEHOLDER) if name == "index.html" else HTMLResponse("not found", status_code=404)
