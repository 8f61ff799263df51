"""``/api/health``: which services are alive, and whether data is flowing.

It answers 503 (with the same body) whenever the status is not ``ok``, so a load balancer, a
container probe or a monitoring check can act on the code alone.
"""

from __future__ import annotations

from fastapi import APIRouter, Request, Response

from bevflow_services.gateway.params import StateDep
from bevflow_services.gateway.site_health import NOT_OK, Health, site_health

router = APIRouter(prefix="/api", tags=["health"])


@router.get("/health", response_model=Health, summary="Live services and data flow",
            responses={NOT_OK: {"model": Health, "description": "the status is not ok: no_data, stale or degraded"}})
def health(request: Request, response: Response, state: StateDep) -> Health:
    body = site_health(state, getattr(request.app.state, "bus_stats", None), getattr(request.app.state, "service_metrics", None))
    if body.status != "ok":
        response.status_code = NOT_OK
    return body
