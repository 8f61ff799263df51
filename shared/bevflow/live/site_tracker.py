"""One step of the site's central stage: fuse the cameras' cylinders, track, analyse.

The tracker service calls ``SiteTracker.step`` once per tick (``bevflow.live.assembler``) and
publishes what comes back as it is: the tracks, the occupancy and the events are wire messages.
The evaluation suite calls the same step, so what is scored is what runs live.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bevflow.analytics.engine import AnalyticsTick, SiteAnalytics
from bevflow.detections import Cylinders
from bevflow.fusion import Fusion, fuse_cylinders
from bevflow.schemas import DistanceViolation, Occupancy, OverCapacity, Tracks, TrackState
from bevflow.site import Site
from bevflow.tracking.tracker import Tracker, TrackerConfig, TrackTable


@dataclass(frozen=True, eq=False)
class SiteStep:
    """What one tick produced."""

    tracks: Tracks
    occupancy: Occupancy
    events: list[DistanceViolation | OverCapacity]
    fusion: Fusion
    table: TrackTable
    analytics: AnalyticsTick


class SiteTracker:
    """Fusion, the one tracker and the analytics of a site, stepped tick by tick.

    ``first_id`` continues the id sequence of a previous run, so a restarted tracker never reuses
    an id that clients or the history already know."""

    def __init__(self, site: Site, tracker_config: TrackerConfig | None = None, first_id: int = 1) -> None:
        self.site = site
        self.camera_ids = site.camera_ids
        self.cameras = [site.camera(c) for c in self.camera_ids]
        self.tracker = Tracker(tracker_config or TrackerConfig.from_thresholds(site.thresholds), first_id=first_id)
        self.analytics = SiteAnalytics(site)

    def step(self, time_ns: int, per_camera: dict[str, Cylinders]) -> SiteStep:
        """Advance to ``time_ns`` with each reporting camera's cylinders (cameras missing from
        ``per_camera`` saw nothing this tick or did not report)."""
        parts = [per_camera[c].with_camera(i) for i, c in enumerate(self.camera_ids) if c in per_camera]
        seen = Cylinders.merge(parts)
        fusion = fuse_cylinders(seen, self.cameras, self.site.thresholds.fusion_distance_m)
        table = self.tracker.update(fusion.fused, time_ns / 1e9)
        tick = self.analytics.update(time_ns, table.id, table.xy, table.velocity)
        tracks = Tracks(
            site=self.site.site,
            time_ns=time_ns,
            tracks=self._track_states(table, self._cameras_of_fused(fusion, seen.camera), tick),
            violations=[(int(a), int(b)) for a, b in tick.violations],
        )
        events = [e.model_copy(update={"raised_ns": time_ns}) for e in tick.events]
        return SiteStep(tracks, tick.occupancy, events, fusion, table, tick)

    def _track_states(self, table: TrackTable, seen_by: list[list[str]], tick: AnalyticsTick) -> list[TrackState]:
        zones = tick.zones_by_track
        return [
            TrackState(
                id=int(table.id[k]),
                xy=(float(table.xy[k, 0]), float(table.xy[k, 1])),
                velocity=(float(table.velocity[k, 0]), float(table.velocity[k, 1])),
                height=float(table.height[k]),
                radius=float(table.radius[k]),
                cameras=seen_by[table.detection[k]] if table.detection[k] >= 0 else [],
                zones=zones.get(int(table.id[k]), []),
            )
            for k in range(len(table))
        ]

    def _cameras_of_fused(self, fusion: Fusion, input_cameras: np.ndarray) -> list[list[str]]:
        """For each fused person, the ids of the cameras whose cylinders were merged into it."""
        out: list[list[str]] = [[] for _ in range(len(fusion.fused))]
        for row, cam in zip(fusion.assignment, input_cameras, strict=True):
            if row < 0:  # not placed on the floor, or a weak view that joined nobody
                continue
            name = self.camera_ids[cam]
            if name not in out[row]:
                out[row].append(name)
        return out
