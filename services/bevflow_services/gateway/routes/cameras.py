"""``/api/cameras``: where each camera hangs and whether its frames are arriving."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel, Field

from bevflow.schemas import iso_utc
from bevflow.site import Site

from bevflow_services.gateway.camera_health import CameraHealth
from bevflow_services.gateway.params import Limit, Offset, Page, StateDep

router = APIRouter(prefix="/api/cameras", tags=["cameras"])


class CameraStatus(BaseModel):
    id: str
    model: Literal["fisheye", "pinhole"]
    position: tuple[float, float, float] = Field(description="camera centre in world metres (Z up)")
    image_size: tuple[int, int]
    monitored_radius_m: float | None = Field(description="radius on the floor the camera is trusted for, if set")
    state: Literal["up", "down", "unknown"]
    reason: str = Field(description="why the camera is down or unknown; empty when up")
    frames_received: int
    frames_dropped: int = Field(description="gaps in the frame sequence numbers since the gateway started")
    last_seq: int | None
    last_capture_ns: int | None
    last_message: str | None = Field(description="when the gateway last heard from the camera, ISO-8601 UTC")
    age_s: float | None = Field(description="seconds since then")


def camera_status(site: Site, health: CameraHealth) -> CameraStatus:
    config = next(c for c in site.cameras if c.id == health.camera)
    center = site.camera(config.id).center
    return CameraStatus(
        id=config.id,
        model=config.model,
        position=(float(center[0]), float(center[1]), float(center[2])),
        image_size=config.image_size,
        monitored_radius_m=config.monitored_radius_m,
        state=health.state,
        reason=health.reason,
        frames_received=health.received,
        frames_dropped=health.dropped,
        last_seq=health.last_seq,
        last_capture_ns=health.last_capture_ns,
        last_message=None if health.last_received_ns is None else iso_utc(health.last_received_ns),
        age_s=health.age_s,
    )


@router.get("", response_model=Page[CameraStatus], summary="Every camera, with its health, in site order")
def cameras(state: StateDep, limit: Limit = 100, offset: Offset = 0) -> Page[CameraStatus]:
    """A page of ``{items, total, limit, offset}`` like every other list (a bare array before)."""
    every = state.camera_health()
    items = [camera_status(state.site, h) for h in every[offset : offset + limit]]
    return Page[CameraStatus](items=items, total=len(every), limit=limit, offset=offset)


@router.get("/{camera_id}", response_model=CameraStatus, summary="One camera, with its health")
def camera(camera_id: str, state: StateDep) -> CameraStatus:
    for health in state.camera_health():
        if health.camera == camera_id:
            return camera_status(state.site, health)
    known = ", ".join(c.id for c in state.site.cameras)
    raise HTTPException(404, f"camera_id: unknown camera {camera_id!r}; known cameras: {known}")
