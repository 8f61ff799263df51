"""``/api/tracks``: the people tracked now, one person's path, and who came close to them."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Request
from pydantic import BaseModel, Field

from bevflow.analytics.fragments import TrackSpan, actionable, merge_fragments
from bevflow.schemas import Contact, TrackState, TrajectoryPoint, iso_utc

from bevflow_services.gateway.auth import AccessDep, Operator
from bevflow_services.gateway.params import (
    LastS,
    Limit,
    Offset,
    SiteDep,
    StateDep,
    TimeRangeDep,
    ZoneParam,
    check_zone,
    recent,
)
from bevflow_services.gateway.trace_audit import record_trace
from bevflow_services.gateway.state import GatewayState

router = APIRouter(prefix="/api/tracks", tags=["tracks"])

TrackId = Annotated[int, Path(ge=0, description="a track id from /api/tracks")]


class TracksNow(BaseModel):
    """The latest tick's tracks, one page of them (all pairs in violation are listed, not paged)."""

    time_ns: int | None = Field(description="capture time of the tick; null before the first one")
    time: str | None
    items: list[TrackState]
    total: int
    limit: int
    offset: int
    violations: list[tuple[int, int]] = Field(description="pairs closer than the social-distance limit now")


class TrackDetail(BaseModel):
    id: int
    active: bool = Field(description="present in the latest tick")
    current: TrackState | None = Field(description="its state in the latest tick, if active")
    points: list[TrajectoryPoint] = Field(description="stored feet positions, oldest first (about one per second)")


class Contacts(BaseModel):
    track: int
    limit_m: float
    contacts: list[Contact] = Field(description="ordered by first contact")


@router.get("", response_model=TracksNow, summary="Tracks now")
def tracks_now(state: StateDep, site: SiteDep, request: Request, access: AccessDep, zone: ZoneParam = None, limit: Limit = 100,
               offset: Offset = 0) -> TracksNow:  # fmt: skip
    """Where everyone is now. Polling it rebuilds paths, so it is audited like the live stream:
    one row when a viewer starts polling (again after ten quiet minutes)."""
    check_zone(site, zone)
    request.app.state.poll_audit.record(request, access, "live_tracks")
    latest = state.tracks
    people = [] if latest is None else [t for t in latest.tracks if zone is None or zone in t.zones]
    people.sort(key=lambda t: t.id)
    return TracksNow(
        time_ns=None if latest is None else latest.time_ns,
        time=None if latest is None else iso_utc(latest.time_ns),
        items=people[offset : offset + limit],
        total=len(people),
        limit=limit,
        offset=offset,
        violations=[] if latest is None else list(latest.violations),
    )


def _current(state: GatewayState, track_id: int) -> TrackState | None:
    latest = state.tracks
    return None if latest is None else next((t for t in latest.tracks if t.id == track_id), None)


def _unknown_track(track_id: int) -> HTTPException:
    return HTTPException(404, f"track_id: no track {track_id} now or in the history (see /api/tracks)")


@router.get("/{track_id}", response_model=TrackDetail, summary="One track: state now and trajectory")
def track(track_id: TrackId, state: StateDep, window: TimeRangeDep, request: Request, access: AccessDep, _: Operator,
          last_s: LastS = None) -> TrackDetail:
    """Tracing a person: needs the operator role, and is written to the audit log."""
    record_trace(request, access, "trajectory", track_id)
    latest = state.tracks
    window = recent(window, last_s, latest.time_ns if latest else None)
    current = _current(state, track_id)
    path = state.history.trajectory(track_id, window.since_ns, window.until_ns)
    if path is None and current is None:
        raise _unknown_track(track_id)
    return TrackDetail(
        id=track_id,
        active=current is not None,
        current=current,
        points=[] if path is None else path.to_points(),
    )


@router.get("/{track_id}/contacts", response_model=Contacts, summary="Who came close to one track")
def track_contacts(
    track_id: TrackId,
    state: StateDep,
    window: TimeRangeDep,
    request: Request,
    access: AccessDep,
    _: Operator,
    distance_m: Annotated[float | None, Query(gt=0, le=50, description="contact distance; default the social distance")] = None,
    min_duration_s: Annotated[float | None, Query(ge=0, description="only contacts lasting at least this long; "
                                                  "default the site's violation_min_duration_s, 0 for every contact")] = None,
    merge: Annotated[bool, Query(description="join the fragments of one person the tracker lost and found again "
                                 "under a new id (Contact.tracks lists them)")] = True,
) -> Contacts:
    """Tracing a person's contacts: needs the operator role, and is written to the audit log."""
    limit_m = distance_m or state.site.thresholds.social_distance_m
    record_trace(request, access, "contacts", track_id, f"distance_m={limit_m:g}")
    found = state.history.contacts(track_id, limit_m, window.since_ns, window.until_ns)
    if found is None:
        if _current(state, track_id) is None:
            raise _unknown_track(track_id)
        found = []  # tracked now but not sampled yet
    if merge:
        found = merge_fragments(found, _spans(state, [c.track for c in found]))
    shortest = state.site.thresholds.violation_min_duration_s if min_duration_s is None else min_duration_s
    return Contacts(track=track_id, limit_m=limit_m, contacts=actionable(found, shortest))


def _spans(state: StateDep, track_ids: list[int]) -> dict[int, TrackSpan]:
    """When and where each of ``track_ids`` was first and last seen, from the history."""
    spans = {}
    for track in track_ids:
        path = state.history.trajectory(track)
        if path is not None and len(path):
            first, last = path.xy[0].tolist(), path.xy[-1].tolist()
            spans[track] = TrackSpan(int(path.times_ns[0]), int(path.times_ns[-1]), (first[0], first[1]), (last[0], last[1]))
    return spans
