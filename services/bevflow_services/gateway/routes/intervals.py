"""``/api/intervals``: the most crowded stretches of time, per zone and for the whole site.

They are computed on request from the one-second occupancy history, with the rules of
``bevflow.analytics.intervals`` (counts above the crowded level; short dips merged; short
intervals dropped).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from fastapi import APIRouter, HTTPException, Query
from pydantic import BaseModel, Field

from bevflow.analytics.intervals import crowded_intervals
from bevflow.schemas import CrowdedInterval, iso_utc
from bevflow.units import NS_PER_S

from bevflow_services.gateway.history import OccupancySample
from bevflow_services.gateway.params import LastS, SiteDep, StateDep, TimeRangeDep, ZoneParam, check_zone, recent
from bevflow_services.gateway.occupancy import site_crowded_level

router = APIRouter(prefix="/api", tags=["occupancy"])


class CrowdedIntervalView(CrowdedInterval):
    start: str = Field(description="ISO-8601 UTC")
    end: str | None = Field(description="ISO-8601 UTC")
    duration_s: float
    ongoing: bool = Field(description="still crowded at the newest sample (end is that sample's time)")


class Intervals(BaseModel):
    items: list[CrowdedIntervalView] = Field(description="ordered by start; zone null means the whole site")


def _view(interval: CrowdedInterval, last: OccupancySample, count_now: int) -> CrowdedIntervalView:
    end_ns = interval.end_ns if interval.end_ns is not None else last.time_ns
    return CrowdedIntervalView(
        **interval.model_dump(),
        start=iso_utc(interval.start_ns),
        end=iso_utc(end_ns),
        duration_s=(end_ns - interval.start_ns) / NS_PER_S,
        ongoing=end_ns == last.time_ns and count_now > interval.level,
    )


@router.get("/intervals", response_model=Intervals, summary="Crowded time intervals")
def intervals(
    state: StateDep,
    site: SiteDep,
    window: TimeRangeDep,
    zone: ZoneParam = None,
    last_s: LastS = None,
    level: Annotated[int | None, Query(ge=0, description="crowded above this count; default the zone's crowded level")] = None,
    min_gap_s: Annotated[float, Query(ge=0, le=3600, description="dips up to this long are merged")] = 30.0,
    min_duration_s: Annotated[float, Query(ge=0, le=86400, description="shorter intervals are dropped")] = 60.0,
) -> Intervals:
    check_zone(site, zone)
    latest = state.occupancy
    window = recent(window, last_s, latest.time_ns if latest else None)
    levels: dict[str | None, int | None] = {}
    if zone is None:
        levels[None] = level if level is not None else site_crowded_level(site)
    for z in site.zones:
        if zone is None or z.id == zone:
            levels[z.id] = level if level is not None else z.effective_crowded_level
    if zone is not None and levels[zone] is None:
        raise HTTPException(400, f"level: zone {zone!r} has no capacity or crowded_level; give level")

    samples = state.history.occupancy(window.since_ns, window.until_ns)
    if not samples:
        return Intervals(items=[])
    times = np.array([s.time_ns for s in samples], dtype=np.int64)
    found: list[CrowdedIntervalView] = []
    for zone_id, zone_level in levels.items():
        if zone_level is None:
            continue
        counts = np.array([s.total if zone_id is None else s.zones.get(zone_id, 0) for s in samples])
        for interval in crowded_intervals(times, counts, zone_level, int(min_gap_s * NS_PER_S), int(min_duration_s * NS_PER_S), zone_id):
            found.append(_view(interval, samples[-1], int(counts[-1])))
    found.sort(key=lambda i: (i.start_ns, i.zone or ""))
    return Intervals(items=found)
