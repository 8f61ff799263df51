"""``/api/site`` (the site description) and ``/api/config`` (what a client needs to connect)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field

from bevflow.schemas import EVENT_TYPES, SCHEMA_VERSION
from bevflow.site import Site

from bevflow_services.gateway.params import SiteDep
from bevflow_services.gateway.view3d_path import PATH as VIEW3D_PATH
from bevflow_services.redact import redact

router = APIRouter(prefix="/api", tags=["site"])


class ClientConfig(BaseModel):
    site: str
    schema_version: int
    view3d_url: str | None = Field(description="the 3D view (viser), a path on this gateway; null if off")
    alert_types: list[str]
    websockets: dict[str, str] = Field(description="websocket paths by stream name")
    social_distance_m: float
    history_s: float = Field(description="how far back the history routes reach")


def redact_source(source: str | None) -> str | None:
    """A camera source with any password in its URL hidden (``rtsp://user:***@host/...``)."""
    return None if source is None else redact(source)


@router.get("/site", response_model=Site, summary="The site description: cameras, zones, thresholds")
def site(site: SiteDep) -> Site:
    """The site as loaded, except that passwords in camera stream URLs are replaced by ``***``."""
    cameras = [c.model_copy(update={"source": redact_source(c.source)}) for c in site.cameras]
    return site.model_copy(update={"cameras": cameras})


@router.get("/config", response_model=ClientConfig, summary="Where the 3D view and the streams are")
def config(request: Request, site: SiteDep) -> ClientConfig:
    return ClientConfig(
        site=site.site,
        schema_version=SCHEMA_VERSION,
        view3d_url=None if request.app.state.view3d_port is None else f"{VIEW3D_PATH}/",
        alert_types=list(EVENT_TYPES),
        websockets={"alerts": "/ws/alerts", "tracks": "/ws/tracks"},
        social_distance_m=site.thresholds.social_distance_m,
        history_s=request.app.state.history_s,
    )
