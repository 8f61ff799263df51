"""``/api/history``: occupancy, alerts and tracks over any time range, paged, or as CSV files.

Every route takes ``since``/``until`` (ISO-8601 or Unix seconds), ``limit``/``offset`` and
``format=json|csv``; a CSV holds the same rows as the JSON page, with the total in the
``X-Total-Count`` header. Occupancy and alerts work with either history (memory or database);
track summaries need the database (``--db``).
"""

from __future__ import annotations

import csv
import io
import re
import unicodedata
from collections.abc import Iterable, Sequence
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel, Field

from bevflow.schemas import EVENT_TYPES, Event, iso_utc
from bevflow.units import NS_PER_S

from bevflow_services.gateway.auth import AccessDep, Operator
from bevflow_services.gateway.event_query import event_query
from bevflow_services.gateway.history import HistoryStore, OccupancySample
from bevflow_services.gateway.params import (
    Offset,
    Page,
    SiteDep,
    StateDep,
    TimeRange,
    TimeRangeDep,
    ZoneParam,
    check_zone,
    split_csv,
)
from bevflow_services.gateway.occupancy import downsample
from bevflow_services.gateway.trace_audit import record_trace

router = APIRouter(prefix="/api/history", tags=["history"])

MAX_ROWS = 100_000
RowLimit = Annotated[int, Query(ge=1, le=MAX_ROWS, description=f"rows per page, 1 to {MAX_ROWS}")]
Format = Annotated[Literal["json", "csv"], Query(alias="format", description="json: one page; csv: the same rows as a file")]
TrackParam = Annotated[int | None, Query(ge=0, description="only alerts that involve this track id")]
ActiveParam = Annotated[bool | None, Query(description="true: only ongoing alerts; false: only ended ones")]
TypesParam = Annotated[str | None, Query(description=f"comma-separated alert types: {', '.join(EVENT_TYPES)}")]
CSV_RESPONSE: dict[int | str, dict[str, Any]] = {
    200: {"content": {"text/csv": {"schema": {"type": "string"}}}, "description": "JSON, or CSV with format=csv"}}


# --- CSV -----------------------------------------------------------------------------------------
# What a spreadsheet may take as the start of a formula ('|' starts a DDE command in some), and
# the control characters that can hide one or break a row. Alert ids come from the bus as any text.
FORMULA_LEADS = frozenset("=+-@|\t\r\n")
PLAIN_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def _cell(value: object) -> object:
    """A CSV cell. Text that a spreadsheet would run as a formula gets a leading ', and control
    characters become U+FFFD; numbers stay as they are (the writer quotes every text cell)."""
    if value is None:
        return ""
    if not isinstance(value, str):
        return value
    text = "".join("\ufffd" if unicodedata.category(c) == "Cc" else c for c in value)
    if value[:1] in FORMULA_LEADS and not PLAIN_NUMBER.fullmatch(value):
        return "'" + text
    return text


def csv_response(name: str, header: Sequence[str], rows: Iterable[Sequence[object]], total: int) -> Response:
    out = io.StringIO()
    # Every text cell quoted: a CR inside one is never taken for the end of a row.
    writer = csv.writer(out, lineterminator="\n", quoting=csv.QUOTE_NONNUMERIC)
    writer.writerow(header)
    writer.writerows([_cell(v) for v in row] for row in rows)
    return Response(out.getvalue(), media_type="text/csv; charset=utf-8",
                    headers={"Content-Disposition": f'attachment; filename="{name}.csv"', "X-Total-Count": str(total)})


# --- occupancy -----------------------------------------------------------------------------------
class OccupancyRow(BaseModel):
    time: str = Field(description="start of the step, ISO-8601 UTC")
    time_ns: int
    total: int = Field(description="highest site-wide count in the step")
    zones: dict[str, int] = Field(description="highest count per zone in the step")


class OccupancyPage(Page[OccupancyRow]):
    step_s: int


def occupancy_steps(history: HistoryStore, window: TimeRange, step_s: int, limit: int,
                    offset: int) -> tuple[list[OccupancySample], int]:
    """Highest counts per step, oldest first: from the database directly when there is one."""
    steps = getattr(history, "occupancy_steps", None)
    if steps is not None:
        return steps(window.since_ns, window.until_ns, step_s, limit, offset)
    samples = history.occupancy(window.since_ns, window.until_ns)
    zone_ids = sorted({z for s in samples for z in s.zones})
    columns = downsample(samples, zone_ids, step_s)
    rows = [OccupancySample(t, columns.total[i], {z: columns.zones[z][i] for z in zone_ids})
            for i, t in enumerate(columns.time_ns)]
    return rows[offset : offset + limit], len(rows)


@router.get("/occupancy", response_model=OccupancyPage, responses=CSV_RESPONSE,
            summary="Occupancy over a time range, per step, paged or as CSV")
def occupancy_history(
    state: StateDep,
    site: SiteDep,
    window: TimeRangeDep,
    zone: ZoneParam = None,
    step_s: Annotated[int, Query(ge=1, le=86400, description="seconds per row; each row is the highest count in it")] = 60,
    limit: RowLimit = 1000,
    offset: Offset = 0,
    fmt: Format = "json",
) -> Any:
    """Rows oldest first. Data older than the fine retention window is stored per minute, so a
    step shorter than that gives one row per stored minute there."""
    check_zone(site, zone)
    samples, total = occupancy_steps(state.history, window, step_s, limit, offset)
    zone_ids = [zone] if zone is not None else [z.id for z in site.zones]
    rows = [OccupancyRow(time=iso_utc(s.time_ns), time_ns=s.time_ns, total=s.total,
                         zones={z: s.zones.get(z, 0) for z in zone_ids}) for s in samples]
    if fmt == "csv":
        return csv_response("occupancy", ["time", "time_ns", "total", *zone_ids],
                            ([r.time, r.time_ns, r.total, *r.zones.values()] for r in rows), total)
    return OccupancyPage(items=rows, total=total, limit=limit, offset=offset, step_s=step_s)


# --- alerts --------------------------------------------------------------------------------------
class EventRow(BaseModel):
    id: str
    type: str
    zone: str | None
    tracks: list[int]
    start: str = Field(description="ISO-8601 UTC")
    end: str | None = Field(description="ISO-8601 UTC; null while ongoing")
    start_ns: int
    end_ns: int | None
    duration_s: float | None = Field(description="how long it lasted; null while ongoing")
    active: bool
    event: Event


def event_row(event: Event) -> EventRow:
    return EventRow(
        id=event.id, type=event.type, zone=event.zone, tracks=list(event.tracks),
        start=iso_utc(event.start_ns), end=None if event.end_ns is None else iso_utc(event.end_ns),
        start_ns=event.start_ns, end_ns=event.end_ns,
        duration_s=None if event.end_ns is None else (event.end_ns - event.start_ns) / NS_PER_S,
        active=event.end_ns is None, event=event,
    )


EVENT_COLUMNS = ["id", "type", "zone", "start", "end", "duration_s", "active", "tracks",
                 "min_distance_m", "peak", "capacity", "camera"]


def _event_csv_row(row: EventRow) -> list[object]:
    detail = row.event
    return [row.id, row.type, row.zone, row.start, row.end, row.duration_s, row.active,
            " ".join(map(str, row.tracks)), getattr(detail, "min_distance_m", None), getattr(detail, "peak", None),
            getattr(detail, "capacity", None), getattr(detail, "camera", None)]


@router.get("/events", response_model=Page[EventRow], responses=CSV_RESPONSE,
            summary="Alerts over a time range with their durations, newest first, paged or as CSV")
def event_history(
    state: StateDep,
    site: SiteDep,
    window: TimeRangeDep,
    types: TypesParam = None,
    zone: ZoneParam = None,
    track: TrackParam = None,
    active: ActiveParam = None,
    limit: RowLimit = 1000,
    offset: Offset = 0,
    fmt: Format = "json",
) -> Any:
    """An alert overlapping [since, until] is listed."""
    query = event_query(site, window, split_csv(types, "types", EVENT_TYPES), zone, track, active)
    events, total = state.history.events(query, limit, offset)
    rows = [event_row(e) for e in events]
    if fmt == "csv":
        return csv_response("events", EVENT_COLUMNS, (_event_csv_row(r) for r in rows), total)
    return Page[EventRow](items=rows, total=total, limit=limit, offset=offset)


# --- tracks --------------------------------------------------------------------------------------
class ZoneVisitView(BaseModel):
    zone: str
    first: str
    last: str
    first_ns: int
    last_ns: int


class TrackSummaryView(BaseModel):
    id: int
    first: str = Field(description="first stored sighting, ISO-8601 UTC")
    last: str = Field(description="last stored sighting, ISO-8601 UTC")
    first_ns: int
    last_ns: int
    duration_s: float
    points: int = Field(description="stored positions (about one per second while tracked)")
    zones: list[ZoneVisitView] = Field(description="zones it was seen in, by first sighting")


@router.get("/tracks", response_model=Page[TrackSummaryView], responses=CSV_RESPONSE,
            summary="Tracks seen in a time range (summaries, no positions), newest first")
def track_history(
    state: StateDep,
    site: SiteDep,
    window: TimeRangeDep,
    request: Request,
    access: AccessDep,
    _: Operator,
    zone: ZoneParam = None,
    limit: RowLimit = 1000,
    offset: Offset = 0,
    fmt: Format = "json",
) -> Any:
    """A track seen at any time within [since, until] is listed. Needs the history database."""
    record_trace(request, access, "track_summaries", None, f"zone={zone or ''}")
    summaries_of = getattr(state.history, "track_summaries", None)
    if summaries_of is None:
        raise HTTPException(404, "track summaries are kept only in the history database: start the gateway with --db")
    summaries, total = summaries_of(window.since_ns, window.until_ns, check_zone(site, zone), limit, offset)
    rows = [TrackSummaryView(
        id=s.track_id, first=iso_utc(s.first_ns), last=iso_utc(s.last_ns), first_ns=s.first_ns, last_ns=s.last_ns,
        duration_s=(s.last_ns - s.first_ns) / NS_PER_S, points=s.points,
        zones=[ZoneVisitView(zone=v.zone, first=iso_utc(v.first_ns), last=iso_utc(v.last_ns), first_ns=v.first_ns,
                             last_ns=v.last_ns) for v in s.zones]) for s in summaries]
    if fmt == "csv":
        return csv_response("tracks", ["id", "first", "last", "duration_s", "points", "zones"],
                            ([r.id, r.first, r.last, r.duration_s, r.points, " ".join(v.zone for v in r.zones)] for r in rows),
                            total)
    return Page[TrackSummaryView](items=rows, total=total, limit=limit, offset=offset)
