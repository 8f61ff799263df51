"""``/metrics``: the site's health for Prometheus (``bevflow_services.gateway.metrics``).

It needs the viewer role like the rest of the read-only API: Prometheus scrapes with an API
token (``bevflow users --db URL token prometheus``) as its bearer credentials. With access
control off (a gateway on loopback) it answers anyone on that machine.
"""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST

from bevflow_services.gateway.metrics import exposition
from bevflow_services.gateway.params import StateDep

router = APIRouter(tags=["health"])


@router.get("/metrics", include_in_schema=False)
def metrics(request: Request, state: StateDep) -> Response:
    extras = request.app.state
    body = exposition(state, getattr(extras, "bus_stats", None), extras.alert_tally, extras.service_metrics)
    return Response(body, media_type=CONTENT_TYPE_LATEST)
