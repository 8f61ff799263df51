"""One step of the site's central stage: fuse the cameras' cylinders, track, analyse.

The tracker service calls ``SiteTracker.step`` once per tick (``bevflow.live.assembler``) and
publishes what comes back as it is: the tracks, the occupancy and the events are wire messages.
The evaluation suite calls the same step, so what is scored is what runs live.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from bevflow.analytics.engine import AnalyticsTick, SiteAnalytics
from bevflow.detections import Cylinders
from bevflow.fusion import Fusion, fuse_cylinders
from bevflow.schemas import DistanceViolation, Occupancy, OverCapacity, Tracks
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
        seen = self._merge_cameras(per_camera)
        fusion = fuse_cylinders(seen, self.cameras, self.site.thresholds.fusion_distance_m)
        table = self.tracker.update(fusion.fused, time_ns / 1e9)
        tick = self.analytics.update(time_ns, table.id, table.xy, table.velocity)
        tracks = self._tracks_message(time_ns, table, self._cameras_of_fused(fusion, seen.camera), tick)
        events = [e.model_copy(update={"raised_ns": time_ns}) for e in tick.events]
        return SiteStep(tracks, tick.occupancy, events, fusion, table, tick)

    def _merge_cameras(self, per_camera: dict[str, Cylinders]) -> Cylinders:
        """Every reporting camera's cylinders in site camera order, ``camera`` set to its index."""
        index = [i for i, c in enumerate(self.camera_ids) if c in per_camera]
        parts = [per_camera[self.camera_ids[i]] for i in index]
        seen = Cylinders.merge(parts)
        return replace(seen, camera=np.repeat(np.asarray(index, dtype=np.int64), [len(p) for p in parts]))

    def _tracks_message(
        self, time_ns: int, table: TrackTable, seen_by: list[list[str]], tick: AnalyticsTick
    ) -> Tracks:
        # One validation of plain lists for the whole message: a thousand tracks would otherwise
        # cost a thousand ``TrackState(...)`` calls, the most expensive part of the tick.
        cameras = [seen_by[d] if d >= 0 else [] for d in table.detection.tolist()]
        columns = (
            table.id.tolist(), table.xy.tolist(), table.velocity.tolist(), table.height.tolist(),
            table.radius.tolist(), cameras, tick.zones_by_row,
        )  # fmt: skip
        states = [
            {"id": i, "xy": xy, "velocity": v, "height": h, "radius": r, "cameras": c, "zones": z}
            for i, xy, v, h, r, c, z in zip(*columns, strict=True)
        ]
        violations = tick.violations.tolist()
        return Tracks.model_validate(
            {"site": self.site.site, "time_ns": time_ns, "tracks": states, "violations": violations}
        )

    def _cameras_of_fused(self, fusion: Fusion, input_cameras: np.ndarray) -> list[list[str]]:
        """For each fused person, the ids of the cameras whose cylinders were merged into it, in
        site camera order."""
        out: list[list[str]] = [[] for _ in range(len(fusion.fused))]
        merged = fusion.assignment >= 0  # not: off the floor, or a weak view that joined nobody
        count = len(self.camera_ids)
        person_camera = np.unique(fusion.assignment[merged] * count + input_cameras[merged])
        for person, camera in zip((person_camera // count).tolist(), (person_camera % count).tolist()):
            out[person].append(self.camera_ids[camera])
        return out
