"""Query parameters shared by several routes, and the checks FastAPI cannot express alone.

Times in queries are ISO-8601 (``2024-05-01T12:00:00Z``; no offset means UTC) or seconds since the
Unix epoch. Every refusal names the parameter: 400 for inconsistent values, 404 for an unknown
zone or track (with the known ids), 422 (FastAPI's own) for a value of the wrong type or range.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Annotated, Generic, TypeVar

from fastapi import Depends, HTTPException, Query
from pydantic import BaseModel
from starlette.requests import HTTPConnection

from bevflow.site import Site
from bevflow.units import NS_PER_S

from bevflow_services.gateway.state import GatewayState

T = TypeVar("T")
MAX_LIMIT = 1000
EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def get_state(conn: HTTPConnection) -> GatewayState:
    return conn.app.state.gateway


def get_site(conn: HTTPConnection) -> Site:
    return conn.app.state.gateway.site


StateDep = Annotated[GatewayState, Depends(get_state)]
SiteDep = Annotated[Site, Depends(get_site)]

Limit = Annotated[int, Query(ge=1, le=MAX_LIMIT, description=f"page size, 1 to {MAX_LIMIT}")]
Offset = Annotated[int, Query(ge=0, description="items to skip, for paging")]
ZoneParam = Annotated[str | None, Query(description="a zone id from /api/site; omit for the whole site")]
Since = Annotated[datetime | None, Query(description="start of the time range: ISO-8601 (UTC if no offset) or Unix seconds")]
Until = Annotated[datetime | None, Query(description="end of the time range: ISO-8601 (UTC if no offset) or Unix seconds")]
LastS = Annotated[
    float | None,
    Query(gt=0, le=7 * 86400, description="only the last this many seconds before the newest data; instead of since"),
]


class Page(BaseModel, Generic[T]):
    """One page of a list: ``items[0]`` is item number ``offset`` of ``total`` matching items."""

    items: list[T]
    total: int
    limit: int
    offset: int


def to_ns(moment: datetime) -> int:
    """A datetime as Unix nanoseconds; a naive datetime is taken as UTC."""
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    delta = moment - EPOCH
    return (delta.days * 86400 + delta.seconds) * NS_PER_S + delta.microseconds * 1000


@dataclass(frozen=True)
class TimeRange:
    since_ns: int | None
    until_ns: int | None


def time_range(since: Since = None, until: Until = None) -> TimeRange:
    """``since``/``until`` as nanoseconds; 400 if they are the wrong way round."""
    since_ns = None if since is None else to_ns(since)
    until_ns = None if until is None else to_ns(until)
    if since_ns is not None and until_ns is not None and since_ns > until_ns:
        raise HTTPException(400, f"since ({since.isoformat()}) is after until ({until.isoformat()})")  # type: ignore[union-attr]
    return TimeRange(since_ns, until_ns)


TimeRangeDep = Annotated[TimeRange, Depends(time_range)]


def recent(window: TimeRange, last_s: float | None, newest_ns: int | None) -> TimeRange:
    """Replace ``since`` by ``newest - last_s`` when ``last_s`` is given (the two exclude each other)."""
    if last_s is None:
        return window
    if window.since_ns is not None:
        raise HTTPException(400, "give either since or last_s, not both")
    if newest_ns is None:
        return window
    return TimeRange(newest_ns - int(last_s * NS_PER_S), window.until_ns)


def check_zone(site: Site, zone: str | None) -> str | None:
    """``zone`` itself if the site has it (or it is None); 404 listing the known zone ids otherwise."""
    if zone is not None and zone not in {z.id for z in site.zones}:
        known = ", ".join(z.id for z in site.zones) or "(the site has no zones)"
        raise HTTPException(404, f"zone: unknown zone {zone!r}; known zones: {known}")
    return zone


def split_csv(value: str | None, name: str, allowed: tuple[str, ...] | None = None) -> frozenset[str] | None:
    """A comma-separated filter as a set; 400 naming ``name`` for a value outside ``allowed``."""
    if value is None or not value.strip():
        return None
    items = frozenset(v.strip() for v in value.split(",") if v.strip())
    if allowed is not None:
        unknown = sorted(items - set(allowed))
        if unknown:
            raise HTTPException(400, f"{name}: unknown value(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}")
    return items
