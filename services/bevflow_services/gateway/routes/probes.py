"""``/healthz`` and ``/readyz``: the gateway's own liveness and readiness, for orchestrator probes.

``/healthz`` answers 200 while the process serves requests. ``/readyz`` answers 200 once tracks
no older than ``STALE_AFTER_S`` reach the gateway (it joined the bus and the tracker's ticks
arrive), 503 otherwise. Unlike ``/api/health`` it stays 200 while the site is merely degraded (a
camera down): taking a working gateway out of service would not bring the camera back.
"""

from __future__ import annotations

from fastapi import APIRouter, Response
from pydantic import BaseModel

from bevflow_services.gateway.params import StateDep
from bevflow_services.gateway.site_health import NOT_OK, STALE_AFTER_S

router = APIRouter(tags=["health"])


class Probe(BaseModel):
    ok: bool
    reason: str = ""


@router.get("/healthz", response_model=Probe, summary="The gateway process is alive")
def healthz() -> Probe:
    return Probe(ok=True)


@router.get("/readyz", response_model=Probe, summary="The gateway receives the tracker's ticks",
            responses={NOT_OK: {"model": Probe, "description": "no tracks yet, or none for a while"}})
def readyz(response: Response, state: StateDep) -> Probe:
    age = state.tracks_age_s()
    if age is not None and age <= STALE_AFTER_S:
        return Probe(ok=True)
    response.status_code = NOT_OK
    if age is None:
        return Probe(ok=False, reason="no tracks received yet: is the tracker running, and this gateway on its bus?")
    return Probe(ok=False, reason=f"the newest tracks arrived {age:.0f} s ago")
