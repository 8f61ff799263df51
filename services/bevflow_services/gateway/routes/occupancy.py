"""``/api/occupancy``: how many people are in the site and in each zone, now and over time."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import BaseModel, Field

from bevflow.schemas import iso_utc

from bevflow_services.gateway.occupancy import Level, OccupancyHistory, downsample, level_of
from bevflow_services.gateway.params import (
    LastS,
    SiteDep,
    StateDep,
    TimeRangeDep,
    ZoneParam,
    check_zone,
    recent,
)

router = APIRouter(prefix="/api/occupancy", tags=["occupancy"])


class ZoneNow(BaseModel):
    id: str
    name: str
    count: int
    capacity: int | None
    crowded_level: int | None
    level: Level = Field(description="count against crowded_level and capacity; 'unknown' if neither is set")


class OccupancyNow(BaseModel):
    """The latest occupancy. Every site zone is listed, at count 0 before the first tracker tick."""

    site: str
    time_ns: int | None = Field(description="capture time of the tick; null before the first one")
    time: str | None
    total: int
    capacity: int | None
    crowded_level: int | None = Field(default=None, description="count from which the whole site is crowded")
    level: Level
    zones: list[ZoneNow]


@router.get("", response_model=OccupancyNow, summary="Occupancy now, site and per zone")
def occupancy_now(state: StateDep) -> OccupancyNow:
    site = state.site
    latest = state.occupancy
    counts = {z.id: z.count for z in latest.zones} if latest else {}
    total = latest.total if latest else 0
    capacity = site.thresholds.site_capacity
    zones = [
        ZoneNow(
            id=z.id,
            name=z.name,
            count=counts.get(z.id, 0),
            capacity=z.capacity,
            crowded_level=z.effective_crowded_level,
            level=level_of(counts.get(z.id, 0), z.effective_crowded_level, z.capacity),
        )
        for z in site.zones
    ]
    return OccupancyNow(
        site=site.site,
        time_ns=latest.time_ns if latest else None,
        time=iso_utc(latest.time_ns) if latest else None,
        total=total,
        capacity=capacity,
        crowded_level=site.crowded_level,
        level=level_of(total, site.crowded_level, capacity),
        zones=zones,
    )


@router.get("/history", response_model=OccupancyHistory, summary="Occupancy over time (one sample per step)")
def occupancy_history(
    state: StateDep,
    site: SiteDep,
    window: TimeRangeDep,
    zone: ZoneParam = None,
    last_s: LastS = None,
    step_s: Annotated[int, Query(ge=1, le=3600, description="seconds per sample; each sample is the maximum in its step")] = 1,
    limit: Annotated[int, Query(ge=1, le=86400, description="at most this many samples, the newest ones")] = 3600,
) -> OccupancyHistory:
    check_zone(site, zone)
    latest = state.occupancy
    window = recent(window, last_s, latest.time_ns if latest else None)
    samples = state.history.occupancy(window.since_ns, window.until_ns)
    zone_ids = [zone] if zone is not None else [z.id for z in site.zones]
    history = downsample(samples, zone_ids, step_s)
    if len(history.time_ns) > limit:
        cut = len(history.time_ns) - limit
        history = OccupancyHistory(
            step_s=step_s,
            time_ns=history.time_ns[cut:],
            total=history.total[cut:],
            zones={z: counts[cut:] for z, counts in history.zones.items()},
        )
    return history
