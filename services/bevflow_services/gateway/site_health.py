"""The site's health as ``/api/health`` reports it (also read by ``/metrics`` and the probes):
which services are alive, and whether data is flowing."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, Field

from bevflow.schemas import iso_utc

from bevflow_services.gateway.state import GatewayState

if TYPE_CHECKING:  # metrics builds on this module
    from bevflow_services.gateway.metrics import ServiceMetricsStore

STALE_AFTER_S = 5.0
Status = Literal["ok", "degraded", "stale", "no_data"]


class ServiceStatus(BaseModel):
    name: str = Field(description="ingest, detector, projector, tracker, gateway, ...")
    instance: str
    since: str = Field(description="when the gateway first saw it alive, ISO-8601 UTC")


class CameraCounts(BaseModel):
    up: int
    down: int
    unknown: int


class Period(BaseModel):
    start: str
    end: str | None = Field(description="null while it lasts")
    start_ns: int
    end_ns: int | None
    reasons: list[str]


class CameraModel(BaseModel):
    camera: str
    model: str = Field(description="the detector model file's name, or rim-tiles")
    provider: str = Field(description="the ONNX Runtime execution provider it runs on, e.g. CPUExecutionProvider")
    instance: str = Field(description="the detector instance serving the camera")


class Health(BaseModel):
    status: Status = Field(
        description="no_data: no tracks yet; stale: no tracks for a while; degraded: the live data is incomplete or "
        "late (see reasons); ok otherwise"
    )
    reasons: list[str] = Field(default_factory=list, description="why the status is degraded: cameras down, behind or "
                               "losing frames, tracks arriving late, ticks skipped")
    degraded_periods: list[Period] = Field(default_factory=list, description="when the data was degraded, the last hour "
                                           "(gateway clock), oldest first")
    site: str
    time: str
    uptime_s: float
    tracks_age_s: float | None = Field(description="seconds since the latest tracks message arrived")
    services: list[ServiceStatus] = Field(description="every service whose liveliness token is present")
    cameras: CameraCounts
    ignored_messages: int = Field(description="messages refused: another site, an unknown camera, out of order")
    bus: dict[str, Any] | None = Field(default=None, description="the bus subscriptions' counters, when fed from the bus")
    detector_models: list[CameraModel] = Field(default_factory=list, description="which model and execution provider each "
                                               "camera's detector runs, as the detectors last reported it (every 5 s)")


NOT_OK = 503  # Service Unavailable: what load balancers and probes take as "not ready"


def site_health(state: GatewayState, bus_stats: Any = None, services: ServiceMetricsStore | None = None) -> Health:
    """The site's health now, as ``/api/health`` reports it (also read by ``/metrics``);
    ``services``: what the services last reported about themselves."""
    now = state.clock()
    cameras = [c.state for c in state.camera_health()]
    counts = CameraCounts(up=cameras.count("up"), down=cameras.count("down"), unknown=cameras.count("unknown"))
    age = state.tracks_age_s()
    reasons, periods = state.degraded()
    status: Status
    if age is None:
        status = "no_data"
    elif age > STALE_AFTER_S:
        status = "stale"
    elif counts.down or reasons:
        status = "degraded"
    else:
        status = "ok"
    return Health(
        status=status,
        site=state.site.site,
        time=iso_utc(now),
        uptime_s=max(0.0, (now - state.started_ns) / 1e9),
        tracks_age_s=age,
        services=[ServiceStatus(name=s.name, instance=s.instance, since=iso_utc(s.since_ns)) for s in state.services()],
        cameras=counts,
        reasons=reasons,
        degraded_periods=[Period(start=iso_utc(p.start_ns), end=None if p.end_ns is None else iso_utc(p.end_ns),
                                 start_ns=p.start_ns, end_ns=p.end_ns, reasons=p.reasons) for p in periods],
        ignored_messages=state.ignored,
        bus=None if bus_stats is None else bus_stats.snapshot(),
        detector_models=[] if services is None else detector_models(services),
    )


def detector_models(services: ServiceMetricsStore) -> list[CameraModel]:
    """Each camera's model and execution provider, from the detectors' ``detector_model_info``."""
    found = [CameraModel(camera=v.labels.get("camera", ""), model=v.labels.get("model", ""), provider=v.labels.get("provider", ""),
                         instance=m.instance)
             for m in services.current() if m.service == "detector" for v in m.values if v.name == "detector_model_info"]  # fmt: skip
    return sorted(found, key=lambda c: (c.camera, c.instance))
