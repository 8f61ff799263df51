"""Every message that crosses a process boundary, defined once.

Zenoh payloads, REST bodies and websocket messages all use these models. They are frozen, reject
unknown fields, and carry ``schema_version`` so a service can refuse a message from a newer
release with a clear log line instead of misreading it.

Conventions: world positions in metres (X, Y on the floor), times as capture timestamps in integer
nanoseconds since the Unix epoch (``*_ns``), pixel boxes as (x0, y0, x1, y1).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated, Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray
import orjson
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    TypeAdapter,
    model_serializer,
    model_validator,
)

from bevflow.detections import Boxes, Cylinders

SCHEMA_VERSION: Literal[1] = 1

Finite = Annotated[float, Field(allow_inf_nan=False)]
Xy = tuple[Finite, Finite]


class Message(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    schema_version: Literal[1] = SCHEMA_VERSION


# --- per camera ---------------------------------------------------------------------------------
class FrameHeader(Message):
    """Metadata sent beside a frame's pixels (the pixels travel as raw bytes or JPEG)."""

    camera: str
    seq: Annotated[int, Field(ge=0)]
    capture_ns: Annotated[int, Field(ge=0)]
    width: Annotated[int, Field(gt=0)]
    height: Annotated[int, Field(gt=0)]
    encoding: Literal["bgr8", "jpeg", "gray8"] = "bgr8"


class Detections2D(Message):
    """One camera's person boxes in one frame."""

    camera: str
    seq: Annotated[int, Field(ge=0)]
    capture_ns: Annotated[int, Field(ge=0)]
    boxes: list[tuple[Finite, Finite, Finite, Finite]] = Field(default_factory=list)
    confidence: list[Annotated[float, Field(ge=0, le=1)]] = Field(default_factory=list)

    @model_validator(mode="after")
    def _one_confidence_per_box(self) -> Detections2D:
        if self.confidence and len(self.confidence) != len(self.boxes):
            raise ValueError(f"{len(self.confidence)} confidences for {len(self.boxes)} boxes")
        return self

    def to_boxes(self) -> Boxes:
        return Boxes(xyxy=np.asarray(self.boxes, dtype=np.float64).reshape(-1, 4), confidence=self.confidence or None)

    @classmethod
    def from_boxes(cls, camera: str, seq: int, capture_ns: int, boxes: Boxes) -> Detections2D:
        return cls(
            camera=camera,
            seq=seq,
            capture_ns=capture_ns,
            boxes=[(float(x0), float(y0), float(x1), float(y1)) for x0, y0, x1, y1 in boxes.xyxy],
            confidence=[float(c) for c in np.clip(boxes.confidence, 0.0, 1.0)],
        )


class CylinderEstimate(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    xy: Xy
    height: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    radius: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    score: Annotated[float, Field(ge=0, le=1)] = 1.0
    occluded: bool = False
    covariance: tuple[Finite, Finite, Finite] | None = Field(
        default=None,
        description="(xx, xy, yy) covariance of the feet position, m²; absent: the receiver computes it",
    )
    stature: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = Field(
        default=None, description="the person's head height as the box measures it, m; absent: not measured"
    )

    @model_validator(mode="after")
    def _covariance_is_positive_definite(self) -> CylinderEstimate:
        if self.covariance is not None:
            xx, xy, yy = self.covariance
            if not (xx > 0 and yy > 0 and xx * yy > xy * xy):
                raise ValueError(f"covariance {self.covariance} is not positive definite")
        return self

    @model_serializer(mode="wrap")
    def _omit_absent_fields(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # An estimate without them serialises as before the fields existed.
        out: dict[str, Any] = handler(self)
        for name in ("covariance", "stature"):
            if getattr(self, name) is None:
                out.pop(name, None)
        return out


class CameraCylinders(Message):
    """One camera's people as world cylinders in one frame."""

    camera: str
    seq: Annotated[int, Field(ge=0)]
    capture_ns: Annotated[int, Field(ge=0)]
    cylinders: list[CylinderEstimate] = Field(default_factory=list)

    def to_cylinders(self, camera_index: int) -> Cylinders:
        c = self.cylinders
        covariance = None
        if any(e.covariance is not None for e in c):
            nan = (np.nan, np.nan, np.nan)
            xx, xy, yy = np.asarray([e.covariance or nan for e in c], dtype=np.float64).T
            covariance = np.stack([np.stack([xx, xy], axis=1), np.stack([xy, yy], axis=1)], axis=1)
        return Cylinders(
            xy=np.asarray([e.xy for e in c], dtype=np.float64).reshape(-1, 2),
            height=[e.height for e in c],
            radius=[e.radius for e in c],
            camera=[camera_index] * len(c),
            score=[e.score for e in c],
            occluded=[e.occluded for e in c],
            covariance=covariance,
            stature=[np.nan if e.stature is None else e.stature for e in c],
        )

    @classmethod
    def from_cylinders(cls, camera: str, seq: int, capture_ns: int, cyl: Cylinders) -> CameraCylinders:
        finite = np.isfinite(cyl.xy).all(axis=1) & np.isfinite(cyl.height) & np.isfinite(cyl.radius)
        finite &= (cyl.height > 0) & (cyl.radius > 0)
        covariance: list[tuple[float, float, float] | None] = [None] * len(cyl)
        if cyl.covariance is not None:
            xx, xy, yy = cyl.covariance[:, 0, 0], cyl.covariance[:, 0, 1], cyl.covariance[:, 1, 1]
            with np.errstate(invalid="ignore", over="ignore"):
                usable = np.isfinite(cyl.covariance).all(axis=(1, 2)) & (xx > 0) & (yy > 0) & (xx * yy > xy * xy)
            covariance = [(a, b, c) if ok else None for a, b, c, ok in zip(xx.tolist(), xy.tolist(), yy.tolist(), usable, strict=True)]
        return cls(
            camera=camera,
            seq=seq,
            capture_ns=capture_ns,
            cylinders=[
                CylinderEstimate(
                    xy=(float(cyl.xy[i, 0]), float(cyl.xy[i, 1])),
                    height=float(cyl.height[i]),
                    radius=float(cyl.radius[i]),
                    score=float(np.clip(cyl.score[i], 0.0, 1.0)),
                    occluded=bool(cyl.occluded[i]),
                    covariance=covariance[i],
                    stature=float(cyl.stature[i]) if cyl.stature[i] > 0 and np.isfinite(cyl.stature[i]) else None,
                )
                for i in np.flatnonzero(finite)
            ],
        )


class SimulatedTruth(Message):
    """A simulated ingest's ground truth for one frame: the people on the monitored floor, with
    the simulator's track ids. Lets tests and benchmarks score the live system end to end."""

    site: str
    frame: Annotated[int, Field(ge=0)]
    capture_ns: Annotated[int, Field(ge=0)]
    tracks: list[int] = Field(default_factory=list)
    positions: list[Xy] = Field(default_factory=list)


# --- site-wide, from the tracker ------------------------------------------------------------------
class TrackState(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    id: int
    xy: Xy
    velocity: Xy = (0.0, 0.0)
    height: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 1.7
    radius: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 0.3
    cameras: list[str] = Field(default_factory=list, description="cameras that saw this person in this tick")
    zones: list[str] = Field(default_factory=list)


class Tracks(Message):
    """All active tracks of the site at one tick."""

    site: str
    time_ns: Annotated[int, Field(ge=0)]
    tracks: list[TrackState] = Field(default_factory=list)
    violations: list[tuple[int, int]] = Field(default_factory=list, description="pairs closer than the limit now")

    @staticmethod
    def wire_json(
        site: str,
        time_ns: int,
        columns: TrackColumns,
        cameras: list[list[str]],
        zones: list[list[str]],
        violations: list[tuple[int, int]] | list[list[int]],
    ) -> bytes:
        """This message's JSON written straight from the tracker's columns (one row per person),
        without a ``TrackState`` per person: validating a thousand of them took longer than
        fusing and tracking the site. Subscribers validate what arrives as usual; here the columns
        are checked in bulk for what the fields require, and a bad one raises (publishing a wrong
        message is a bug). Metres and metres per second are rounded to 0.1 mm. orjson writes the same
        bytes as pydantic's encoder in 40 % of its time (a thousand rows: 0.23 against 0.57 ms)."""
        n = len(columns.id)
        if not (len(cameras) == len(zones) == n and columns.xy.shape == columns.velocity.shape == (n, 2)):
            raise ValueError("every track column must have one row per track")
        # 0.1 mm (and mm/s) is far below what any camera tells apart, and a third fewer bytes to
        # send and for every subscriber to parse.
        xy, velocity, height, radius = (np.round(c, 4) for c in (columns.xy, columns.velocity, columns.height, columns.radius))
        finite = np.isfinite(xy).all() and np.isfinite(velocity).all()
        if not (finite and time_ns >= 0 and (height > 0).all() and (radius > 0).all()):
            raise ValueError("tracks need finite positions and velocities, heights and radii > 0, time_ns >= 0")
        columns_out = (columns.id.tolist(), xy.tolist(), velocity.tolist(), height.tolist(), radius.tolist())
        rows = zip(*columns_out, cameras, zones, strict=True)
        states = [
            {"id": i, "xy": p, "velocity": v, "height": h, "radius": r, "cameras": c, "zones": z}
            for i, p, v, h, r, c, z in rows
        ]
        message = {"schema_version": SCHEMA_VERSION, "site": site, "time_ns": int(time_ns), "tracks": states,
                   "violations": violations}  # fmt: skip
        return orjson.dumps(message)


class TrackColumns(Protocol):
    """What ``Tracks.wire_json`` reads of a tracker's table: ``id`` (N,), ``xy`` and ``velocity``
    (N, 2), ``height`` and ``radius`` (N,). Read-only: the tracker's table is frozen."""

    @property
    def id(self) -> NDArray[np.int64]: ...
    @property
    def xy(self) -> NDArray[np.float64]: ...
    @property
    def velocity(self) -> NDArray[np.float64]: ...
    @property
    def height(self) -> NDArray[np.float64]: ...
    @property
    def radius(self) -> NDArray[np.float64]: ...


class ZoneOccupancy(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    id: str
    name: str = ""
    count: Annotated[int, Field(ge=0)]
    capacity: Annotated[int, Field(ge=0)] | None = None


class Occupancy(Message):
    site: str
    time_ns: Annotated[int, Field(ge=0)]
    total: Annotated[int, Field(ge=0)]
    capacity: Annotated[int, Field(ge=0)] | None = None
    zones: list[ZoneOccupancy] = Field(default_factory=list)


# --- analytics results, served over REST ----------------------------------------------------------
class CrowdedInterval(BaseModel):
    """A stretch of time when a zone (or the whole site, ``zone`` None) held more than ``level``
    people; short dips are merged into it. ``end_ns`` is None while it lasts."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    zone: str | None = None
    level: Annotated[int, Field(ge=0)]
    start_ns: Annotated[int, Field(ge=0)]
    end_ns: Annotated[int, Field(ge=0)] | None = None
    peak: Annotated[int, Field(ge=0)]
    peak_ns: Annotated[int, Field(ge=0)]


class TrajectoryPoint(BaseModel):
    """One stored sample of a track's feet position."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    time_ns: Annotated[int, Field(ge=0)]
    xy: Xy


class Contact(BaseModel):
    """Another track that came within ``limit_m`` of a traced track."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    track: int = Field(description="the other track's id")
    first_ns: Annotated[int, Field(ge=0)]
    last_ns: Annotated[int, Field(ge=0)]
    duration_s: Annotated[float, Field(ge=0, allow_inf_nan=False)]
    min_distance_m: Annotated[float, Field(ge=0, allow_inf_nan=False)]
    closest_ns: Annotated[int, Field(ge=0)]
    limit_m: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    tracks: list[int] = Field(default_factory=list, description="when the tracker lost the other person and found them "
                              "again under new ids: every id of theirs merged into this contact, in order")


# --- events --------------------------------------------------------------------------------------
class EventBase(Message):
    """An alert. ``start_ns`` is when the condition began; ``end_ns`` is set once it is over, and the
    same ``id`` is published again then, so subscribers can update the alert in place."""

    id: str
    start_ns: Annotated[int, Field(ge=0)]
    end_ns: Annotated[int, Field(ge=0)] | None = None
    zone: str | None = None
    tracks: list[int] = Field(default_factory=list)
    raised_ns: Annotated[int, Field(ge=0)] | None = Field(
        default=None, description="capture time of the data that raised (or ended) this message; "
        "delivery time minus it is the alert's latency")


class DistanceViolation(EventBase):
    type: Literal["distance_violation"] = "distance_violation"
    min_distance_m: Annotated[float, Field(ge=0, allow_inf_nan=False)]
    limit_m: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    position: Xy | None = Field(default=None, description="midpoint of the pair at the closest approach")
    group: bool = Field(
        default=False,
        description="the pair stayed close for group_after_s and is now taken as a group (a family, a couple): "
        "this end message withdraws the alert, and the pair raises no more",
    )


class DistanceIncident(EventBase):
    """People too close, grouped: everyone linked by distance violations at once is one incident
    (``bevflow.analytics.incidents``). Published when it opens, again (same ``id``) when its people
    change, and when it closes; ``tracks`` lists everyone involved so far."""

    type: Literal["distance_incident"] = "distance_incident"
    people: Annotated[int, Field(ge=2)] = Field(description="the most people in the group at one time")
    current: list[int] = Field(default_factory=list, description="the tracks in the group at the latest tick")
    min_distance_m: Annotated[float, Field(ge=0, allow_inf_nan=False)]
    limit_m: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    position: Xy | None = Field(default=None, description="centre of the group at the latest tick")
    last_active_ns: Annotated[int, Field(ge=0)] = Field(description="the latest tick with a violation in the group")
    severity: Literal["low", "medium", "high"] = Field(description="from the number of people and the duration")
    needs_acknowledgement: bool = Field(
        default=True, description="false once an incident that ended was short: nothing to act on any more")


class OverCapacity(EventBase):
    type: Literal["over_capacity"] = "over_capacity"
    capacity: Annotated[int, Field(ge=0)]
    peak: Annotated[int, Field(ge=0)]


class CalibrationDrift(EventBase):
    type: Literal["calibration_drift"] = "calibration_drift"
    camera: str
    shift_m: Annotated[float, Field(ge=0, allow_inf_nan=False)]
    reference_camera: str | None = None


class CameraHealthEvent(EventBase):
    type: Literal["camera_down", "camera_up"]
    camera: str
    reason: str = ""


Event = Annotated[
    DistanceViolation | DistanceIncident | OverCapacity | CalibrationDrift | CameraHealthEvent,
    Field(discriminator="type"),
]
EVENT_ADAPTER: TypeAdapter[Event] = TypeAdapter(Event)
EVENT_TYPES: tuple[str, ...] = (
    "distance_violation", "distance_incident", "over_capacity", "calibration_drift", "camera_down", "camera_up")
# What an alert feed gets unless it asks by type: the pair events are the raw material of the
# incidents (one per pair of people), kept for integrations that ask for them.
FEED_EVENT_TYPES: tuple[str, ...] = tuple(t for t in EVENT_TYPES if t != "distance_violation")


def decode_event(payload: bytes | str) -> Event:
    return EVENT_ADAPTER.validate_json(payload)


class OpenAlerts(Message):
    """The ids of the alerts the tracker still has open, published every few seconds: it renews
    their lease (``bevflow.alert_lease``), and an open alert nobody renews ends by itself."""

    site: str
    time_ns: Annotated[int, Field(ge=0)]
    ids: list[str] = Field(default_factory=list)


# --- a service's own measurements, for the gateway's /metrics --------------------------------------
SeriesName = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,63}$")]
SeriesLabels = Annotated[dict[str, Annotated[str, Field(max_length=64)]], Field(max_length=4)]


class MetricSeries(BaseModel):
    """A counter (total since the process started) or a gauge (a value now)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: SeriesName
    labels: SeriesLabels = Field(default_factory=dict)
    value: Finite


class HistogramSeries(BaseModel):
    """Observations since the process started: ``counts[i]`` of them at most ``bounds[i]``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: SeriesName
    labels: SeriesLabels = Field(default_factory=dict)
    bounds: Annotated[list[Finite], Field(max_length=32)]
    counts: Annotated[list[Annotated[int, Field(ge=0)]], Field(max_length=32)]
    count: Annotated[int, Field(ge=0)]
    sum: Finite

    @model_validator(mode="after")
    def _one_count_per_bound(self) -> HistogramSeries:
        if len(self.counts) != len(self.bounds):
            raise ValueError(f"{len(self.bounds)} bounds but {len(self.counts)} counts")
        return self


class ServiceMetrics(Message):
    """What one service instance measured about itself (``bevflow_services.service_metrics``),
    published every few seconds; the gateway serves it on ``/metrics``."""

    site: str
    service: str
    instance: str
    time_ns: Annotated[int, Field(ge=0)]
    values: Annotated[list[MetricSeries], Field(max_length=256)] = Field(default_factory=list)
    histograms: Annotated[list[HistogramSeries], Field(max_length=64)] = Field(default_factory=list)


def zones_named(message: BaseModel) -> set[str]:
    """The zone ids a tracker message names (its tracks', counts' or alert's), for a receiver to
    check against its site: a forged id must not reach the history, the API or a CSV export.

    >>> zones_named(Occupancy(site="s", time_ns=0, total=1, zones=[ZoneOccupancy(id="gate", count=1)]))
    {'gate'}
    """
    if isinstance(message, Tracks):
        return {zone for track in message.tracks for zone in track.zones}
    if isinstance(message, Occupancy):
        return {zone.id for zone in message.zones}
    zone = getattr(message, "zone", None)
    return {zone} if isinstance(zone, str) else set()


# --- to websocket and REST clients ---------------------------------------------------------------
def iso_utc(time_ns: int) -> str:
    """``time_ns`` (nanoseconds since the Unix epoch) as ISO-8601 UTC with milliseconds and a ``Z``."""
    seconds, rest = divmod(int(time_ns), 1_000_000_000)
    stamp = datetime.fromtimestamp(seconds, tz=UTC).replace(microsecond=rest // 1000)
    return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")


class AlertMessage(Message):
    """An event as the gateway sends it on ``/ws/alerts`` and lists it over REST.

    ``start``/``end`` are ISO-8601 UTC strings (``2024-05-01T12:00:00.250Z``) that browsers parse
    directly; ``start_ns``/``end_ns`` keep the exact capture times. ``event`` is the full event.
    """

    id: str
    type: Literal["distance_violation", "distance_incident", "over_capacity", "calibration_drift", "camera_down", "camera_up"]
    zone: str | None = None
    tracks: list[int] = Field(default_factory=list)
    start: str = Field(description="when the condition began, ISO-8601 UTC")
    end: str | None = Field(default=None, description="when it ended, ISO-8601 UTC; null while active")
    start_ns: Annotated[int, Field(ge=0)]
    end_ns: Annotated[int, Field(ge=0)] | None = None
    active: bool
    event: Event

    @classmethod
    def from_event(cls, event: Event) -> AlertMessage:
        return cls(
            id=event.id,
            type=event.type,
            zone=event.zone,
            tracks=list(event.tracks),
            start=iso_utc(event.start_ns),
            end=None if event.end_ns is None else iso_utc(event.end_ns),
            start_ns=event.start_ns,
            end_ns=event.end_ns,
            active=event.end_ns is None,
            event=event,
        )
