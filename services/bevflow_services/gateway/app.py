"""The gateway's FastAPI application: REST routes, websockets, the dashboard, and the 3D view.

``create_app`` needs only a site and a ``GatewayState``; it knows nothing of the bus, so tests
feed the state directly and ``main`` feeds it from Zenoh.

>>> from bevflow_services.gateway import GatewayState, create_app  # doctest: +SKIP
>>> app = create_app(site, GatewayState(site))                        # doctest: +SKIP
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import Depends, FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import TypeAdapter

import bevflow_dashboard
from bevflow.schemas import AlertMessage, Tracks
from bevflow.site import Site

from bevflow_services.gateway.alert_replay import RecentAlerts
from bevflow_services.gateway.api_docs import add_api_docs
from bevflow_services.gateway.metrics import AlertTally, ServiceMetricsStore
from bevflow_services.gateway.trace_audit import PollAudit
from bevflow_services.gateway.auth import Access, HashingBusy, require_role
from bevflow_services.gateway.body_limit import BodyLimit
from bevflow_services.gateway.cross_site import CrossSiteGuard
from bevflow_services.gateway.dashboard_files import serve_dashboard
from bevflow_services.gateway.auth_headers import add_security_middleware
from bevflow_services.gateway.routes import acknowledge, alerts, cameras, health, intervals, occupancy, streams, tracks
from bevflow_services.gateway.routes import auth as auth_routes
from bevflow_services.gateway.routes import calibration as calibration_routes
from bevflow_services.gateway.routes import history as history_routes
from bevflow_services.gateway.routes import metrics as metrics_routes
from bevflow_services.gateway.routes import probes
from bevflow_services.gateway.routes import reports
from bevflow_services.gateway.routes import site as site_routes
from bevflow_services.gateway.routes import view3d as view3d_routes
from bevflow_services.gateway.routes import users as users_routes
from bevflow_services.gateway.state import GatewayState
from bevflow_services.storage import StorageError

log = logging.getLogger(__name__)

DASHBOARD_DIR = Path(bevflow_dashboard.__file__).resolve().parent
API_VERSION = "1"

WEBSOCKETS_DOC = {
    "/ws/alerts": {
        "description": "One AlertMessage per text frame, when an alert starts, again when it changes or ends (same id).",
        "query": {
            "types": "comma-separated alert types to receive (default: all but distance_violation, the per-pair "
                     "events that distance_incident groups)",
            "zones": "comma-separated zone ids to receive (default: all, including site-wide alerts)",
            "replay": "'active' to first receive the alerts already ongoing (default: 'none')",
            "since": "the id of the last alert received: first receive, from the history and oldest first, every alert "
                     "whose newest message came after it, each once in its newest state, then the live ones; 400 for "
                     "an id the history does not hold; not with replay=active",
        },
        "message": {"$ref": "#/components/schemas/AlertMessage"},
    },
    "/ws/tracks": {
        "description": "One Tracks message per tracker tick, starting with the latest one.",
        "query": {},
        "message": {"$ref": "#/components/schemas/Tracks"},
    },
}


def create_app(
    site: Site,
    state: GatewayState,
    *,
    dashboard_dir: Path | None = None,
    view3d_port: int | None = None,
    view3d_rate_hz: float = 5.0,
    feed: Callable[[], AbstractAsyncContextManager[object]] | None = None,
    access: Access | None = None,
) -> FastAPI:
    """The gateway application for ``site``, reading ``state``.

    Args:
        dashboard_dir: folder served at ``/`` (default: the installed dashboard); ``/`` shows a
            placeholder page while it has no ``index.html``.
        view3d_port: loopback port of the viser 3D view, started with the app's lifespan and served
            through the gateway at ``/view3d/``; None: no 3D view.
        feed: entered for the app's lifespan, after the 3D view starts: what feeds ``state``
            (``main`` passes the bus subscriptions).
        access: users, roles and security settings (see ``auth``); None: no login, every request
            acts as an admin (what tests and ``--auth off`` on loopback use).
    """
    if state.site is not site and state.site != site:
        raise ValueError(f"the state is for site {state.site.site!r}, not {site.site!r}")
    dashboard = dashboard_dir or DASHBOARD_DIR

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        view = None
        if view3d_port is not None:
            from bevflow_services.gateway.view3d import View3D

            # Loopback only: viser has no login; browsers reach it through /view3d (routes.view3d).
            view = View3D(state, host="127.0.0.1", port=view3d_port, rate_hz=view3d_rate_hz)
            view.start()
            app.state.view3d_port = view.port
        try:
            if feed is None:
                yield
            else:
                async with feed():
                    yield
        finally:
            if view is not None:
                view.stop()
            app.state.view3d_port = None

    app = FastAPI(
        title="bevflow gateway",
        version=API_VERSION,
        summary="Live occupancy, distance alerts and tracks of one site, from ceiling cameras.",
        description=(
            "Units are metres and seconds; `*_ns` fields are capture times in nanoseconds since the Unix epoch, "
            "other times are ISO-8601 UTC. Websockets (not listed as paths): `/ws/alerts` and `/ws/tracks`; "
            "see `x-websockets`."
        ),
        lifespan=lifespan,
        docs_url=None,  # served from local assets by add_api_docs
        redoc_url=None,
    )
    app.state.gateway = state
    app.state.recent_alerts = RecentAlerts()
    state.alerts.observe(app.state.recent_alerts.keep)  # for ?since= replays
    app.state.alert_tally = AlertTally(state.clock)
    state.alerts.observe(app.state.alert_tally.keep)  # for /metrics
    app.state.poll_audit = PollAudit()  # GET /api/tracks: one audit row per viewer's spell of polling
    app.state.service_metrics = ServiceMetricsStore(state.clock)  # what the services report over the bus (main feeds it)
    app.state.view3d_port = None
    app.state.history_s = getattr(state.history, "retention_ns", 3600 * 10**9) / 1e9

    app.state.access = access if access is not None else Access.disabled()
    access = app.state.access

    # Who may call what. Routes that trace a person (a track's path and contacts, track
    # summaries) and acknowledging alerts need the operator role on the route itself; the
    # streams check their clients themselves; health and the probes answer anyone, for load balancers.
    viewer, admin = [Depends(require_role("viewer"))], [Depends(require_role("admin"))]
    for module in (occupancy, intervals, tracks, alerts, cameras, site_routes, history_routes, reports, metrics_routes):
        app.include_router(module.router, dependencies=viewer)
    app.include_router(calibration_routes.router, dependencies=admin)
    for module in (health, probes, streams, acknowledge, auth_routes, users_routes, view3d_routes):
        app.include_router(module.router)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(HashingBusy, _hashing_busy)
    app.add_exception_handler(StorageError, _storage_error)
    app.add_middleware(BodyLimit)
    app.add_middleware(CrossSiteGuard, access=access)
    add_security_middleware(app, access.cors_origins, hsts=access.secure_cookies)
    add_api_docs(app, app.title)
    serve_dashboard(app, dashboard)  # last: it answers every GET no other route claimed
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    return app


async def _validation_error(request: Request, exc: Exception) -> JSONResponse:
    """FastAPI's 422 body, plus one ``message`` line naming the first bad parameter."""
    assert isinstance(exc, RequestValidationError)
    errors = exc.errors()
    first = errors[0] if errors else {"loc": (), "msg": "invalid request"}
    where = ".".join(str(p) for p in first["loc"][1:]) or "request"
    kind = first["loc"][0] if first["loc"] else "request"
    message = f"{kind} parameter {where}: {first['msg']}"
    return JSONResponse(status_code=422, content={"message": message, "detail": jsonable_encoder(errors)})


async def _hashing_busy(request: Request, exc: Exception) -> JSONResponse:
    """503 at once when every password-hashing slot is taken (a login flood), instead of queueing."""
    return JSONResponse(status_code=503, content={"detail": str(exc)}, headers={"Retry-After": "1"})


async def _storage_error(request: Request, exc: Exception) -> JSONResponse:
    """The history database failed (down, or a damaged file): 503 with its one line, and the
    live data, served from memory, goes on."""
    log.error("%s %s: %s", request.method, request.url.path, exc)
    return JSONResponse(status_code=503, content={"detail": str(exc)})


def _openapi(app: FastAPI) -> dict[str, Any]:
    """FastAPI's spec, plus the websocket message schemas (websocket routes are not in OpenAPI)."""
    if app.openapi_schema is not None:
        return app.openapi_schema
    from fastapi.openapi.utils import get_openapi

    spec = get_openapi(title=app.title, version=app.version, summary=app.summary, description=app.description, routes=app.routes)
    schemas = spec.setdefault("components", {}).setdefault("schemas", {})
    for name, model in (("AlertMessage", AlertMessage), ("Tracks", Tracks)):
        model_schema = TypeAdapter(model).json_schema(ref_template="#/components/schemas/{model}")
        for def_name, definition in model_schema.pop("$defs", {}).items():
            schemas.setdefault(def_name, definition)
        schemas.setdefault(name, model_schema)
    spec["x-websockets"] = WEBSOCKETS_DOC
    app.openapi_schema = spec
    return spec
