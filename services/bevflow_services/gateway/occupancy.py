"""Occupancy shared by the occupancy and history routes, the daily report and the 3D view: the
level a count stands at, the site's crowded level, and one-second samples grouped into steps."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel

from bevflow.site import Site
from bevflow.units import NS_PER_S

from bevflow_services.gateway.history import OccupancySample

Level = Literal["unknown", "normal", "crowded", "over_capacity"]


class OccupancyHistory(BaseModel):
    """Occupancy over time, column by column: ``total[i]`` and ``zones[z][i]`` are the highest
    counts in the ``step_s`` seconds starting at ``time_ns[i]``."""

    step_s: int
    time_ns: list[int]
    total: list[int]
    zones: dict[str, list[int]]


def level_of(count: int, crowded_level: int | None, capacity: int | None) -> Level:
    if capacity is not None and count > capacity:
        return "over_capacity"
    if crowded_level is not None and count >= crowded_level:
        return "crowded"
    if capacity is None and crowded_level is None:
        return "unknown"
    return "normal"


def site_crowded_level(site: Site) -> int | None:
    """The site's crowded level (``Site.crowded_level``)."""
    return site.crowded_level


def downsample(samples: list[OccupancySample], zone_ids: list[str], step_s: int) -> OccupancyHistory:
    """Group one-second samples into ``step_s`` steps, keeping each step's maximum."""
    if not samples:
        return OccupancyHistory(step_s=step_s, time_ns=[], total=[], zones={z: [] for z in zone_ids})
    seconds = np.array([s.time_ns // NS_PER_S for s in samples], dtype=np.int64)
    steps, first = np.unique(seconds // step_s, return_index=True)

    def column(values: list[int]) -> list[int]:
        return np.maximum.reduceat(np.asarray(values, dtype=np.int64), first).tolist()

    return OccupancyHistory(
        step_s=step_s,
        time_ns=(steps * step_s * NS_PER_S).tolist(),
        total=column([s.total for s in samples]),
        zones={z: column([s.zones.get(z, 0) for s in samples]) for z in zone_ids},
    )
