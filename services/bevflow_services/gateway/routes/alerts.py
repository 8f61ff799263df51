"""``/api/alerts``, ``/api/incidents`` and ``/api/violations``: alerts past and active.

``/api/alerts`` lists what a supervisor acts on: distance incidents (people too close, grouped),
over capacity, camera and calibration alerts. The per-pair ``distance_violation`` events behind
the incidents are listed only when asked for by type (``?types=distance_violation``) and by
``/api/violations``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import Field
from starlette.requests import HTTPConnection

from bevflow.schemas import EVENT_TYPES, FEED_EVENT_TYPES, AlertMessage

from bevflow_services.gateway.acknowledgements import AcknowledgementView, acknowledgements_of
from bevflow_services.gateway.event_query import event_query
from bevflow_services.gateway.history import EventQuery
from bevflow_services.gateway.params import (
    Limit,
    Offset,
    Page,
    SiteDep,
    StateDep,
    TimeRangeDep,
    ZoneParam,
    split_csv,
)

router = APIRouter(prefix="/api", tags=["alerts"])

TrackParam = Annotated[int | None, Query(ge=0, description="only alerts that involve this track id")]
ActiveParam = Annotated[bool | None, Query(description="true: only ongoing alerts; false: only ended ones")]
TypesParam = Annotated[str | None, Query(
    description=f"comma-separated alert types: {', '.join(EVENT_TYPES)}; default: all but distance_violation "
    "(the per-pair events grouped into distance_incident)")]


class AlertItem(AlertMessage):
    """An alert as ``/ws/alerts`` sends it, with who has acknowledged it."""

    acknowledgements: list[AcknowledgementView] = Field(default_factory=list, description="oldest first; empty: nobody yet")


def _page(state: StateDep, conn: HTTPConnection, query: EventQuery, limit: int, offset: int) -> Page[AlertItem]:
    events, total = state.history.events(query, limit, offset)
    acks = acknowledgements_of(conn, [e.id for e in events])
    items = [AlertItem(**AlertMessage.from_event(e).model_dump(), acknowledgements=acks.get(e.id, [])) for e in events]
    return Page[AlertItem](items=items, total=total, limit=limit, offset=offset)


@router.get("/violations", response_model=Page[AlertItem], summary="Distance violations, newest first")
def violations(
    state: StateDep,
    conn: HTTPConnection,
    site: SiteDep,
    window: TimeRangeDep,
    zone: ZoneParam = None,
    track: TrackParam = None,
    active: ActiveParam = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> Page[AlertItem]:
    """Pairs of people closer than the social-distance limit for longer than the minimum duration.
    A violation overlapping [since, until] is listed; ``event.min_distance_m`` is the closest approach."""
    query = event_query(site, window, frozenset({"distance_violation"}), zone, track, active)
    return _page(state, conn, query, limit, offset)


@router.get("/alerts", response_model=Page[AlertItem], summary="Alerts of every type, newest first")
def alerts(
    state: StateDep,
    conn: HTTPConnection,
    site: SiteDep,
    window: TimeRangeDep,
    types: TypesParam = None,
    zone: ZoneParam = None,
    track: TrackParam = None,
    active: ActiveParam = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> Page[AlertItem]:
    """The same objects ``/ws/alerts`` sends, for filling an alert feed when a page opens."""
    wanted = split_csv(types, "types", EVENT_TYPES) or frozenset(FEED_EVENT_TYPES)
    query = event_query(site, window, wanted, zone, track, active)
    return _page(state, conn, query, limit, offset)


@router.get("/incidents", response_model=Page[AlertItem], summary="Distance incidents, newest first")
def incidents(
    state: StateDep,
    conn: HTTPConnection,
    site: SiteDep,
    window: TimeRangeDep,
    zone: ZoneParam = None,
    track: TrackParam = None,
    active: ActiveParam = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> Page[AlertItem]:
    """Groups of people too close for longer than the site's ``incident_min_duration_s``: one
    incident per group, whoever joins or leaves, closed after ``incident_quiet_s`` without a
    violation. ``event.people`` is the largest the group was; ``event.current`` who is in it now."""
    query = event_query(site, window, frozenset({"distance_incident"}), zone, track, active)
    return _page(state, conn, query, limit, offset)
