"""One step of the site's central stage: fuse the cameras' cylinders, track, analyse.

The tracks follow the fused people, or take the cameras' views themselves where the site says so
or, saying nothing, has side cameras only (``track_views``; ``bevflow.tracking.views``), and the
fusion of the tick is then only what is reported of it (the fused people, the sightings).

The tracker service calls ``SiteTracker.step`` once per tick (``bevflow.live.assembler``) and
publishes what comes back as it is: the tracks, the occupancy and the events are wire messages.
The evaluation suite calls the same step, so what is scored is what runs live.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from bevflow.analytics.engine import AnalyticsTick, SiteAnalytics
from bevflow.detections import Cylinders
# fuse_cylinders is looked up here at each step, so the tracking benchmark can time it by
# wrapping this name: re-exported for that.
from bevflow import fusion as fusion_rules
from bevflow.fusion import Fusion, with_covariance_where_missing
from bevflow.fusion import fuse_cylinders as fuse_cylinders
from bevflow.schemas import DistanceIncident, DistanceViolation, Occupancy, OverCapacity, Tracks
from bevflow.site import Site
from bevflow.tracking.hypotheses import online_tracker
from bevflow.tracking.tracker import TrackerConfig, TrackTable


@dataclass(frozen=True, eq=False)
class SiteStep:
    """What one tick produced. ``tracks_json`` is the ``Tracks`` message as it goes on the wire;
    ``tracks`` reads it back, validated, for callers that want the objects."""

    tracks_json: bytes
    occupancy: Occupancy
    events: list[DistanceViolation | DistanceIncident | OverCapacity]
    fusion: Fusion
    table: TrackTable
    analytics: AnalyticsTick

    @cached_property
    def tracks(self) -> Tracks:
        return Tracks.model_validate_json(self.tracks_json)


class SiteTracker:
    """Fusion, the one tracker and the analytics of a site, stepped tick by tick.

    ``first_id`` continues the id sequence of a previous run, so a restarted tracker never reuses
    an id that clients or the history already know. ``keep_final``: the tracker keeps the updates
    its hypotheses made final (``bevflow.tracking.hypotheses.final_updates``), for an evaluation."""

    def __init__(self, site: Site, tracker_config: TrackerConfig | None = None, first_id: int = 1,
                 keep_final: bool = False) -> None:  # fmt: skip
        self.site = site
        self.camera_ids = site.camera_ids
        self.cameras = [site.camera(c) for c in self.camera_ids]
        config = tracker_config or TrackerConfig.from_thresholds(site.thresholds, self.cameras)
        self.tracker = online_tracker(config, first_id, keep_final, fuse=self._fuse_left_over)
        self.analytics = SiteAnalytics(site)
        self._alone = [[c] for c in self.camera_ids]  # shared lists, read only: serialised as they are

    def step(self, time_ns: int, per_camera: dict[str, Cylinders]) -> SiteStep:
        """Advance to ``time_ns`` with each reporting camera's cylinders (cameras missing from
        ``per_camera`` saw nothing this tick or did not report)."""
        seen = self._merge_cameras(per_camera)
        time_s = time_ns / 1e9
        if self.tracker.config.track_views:
            # The tracks take the views themselves; the fusion is only what the step reports of
            # the instant (the fused people, the sightings), so it needs no priors: matching the
            # views to them again cost a dense solve a tick in a crush.
            views = with_covariance_where_missing(seen, self.cameras)  # each view's weight in its track
            fusion = fuse_cylinders(views, self.cameras, self.site.thresholds.fusion_distance_m)
            table = self.tracker.update(views, time_s, fusion.sightings)
            cameras = self._cameras_of_views(table, seen.camera)
        else:
            expected = self.tracker.predicted(time_s)  # the confirmed tracks guide fusion ("Tracks as priors")
            fusion = fuse_cylinders(seen, self.cameras, self.site.thresholds.fusion_distance_m, priors=expected)
            table = self.tracker.update(fusion.fused, time_s, fusion.sightings)
            seen_by = self._cameras_of_fused(fusion, seen.camera)
            cameras = [seen_by[d] if d >= 0 else [] for d in table.detection.tolist()]
        tick = self.analytics.update(time_ns, table.id, table.xy, table.velocity)
        tracks = Tracks.wire_json(self.site.site, time_ns, table, cameras, tick.zones_by_row, tick.violations.tolist())
        return SiteStep(tracks, tick.occupancy, tick.events, fusion, table, tick)

    def _merge_cameras(self, per_camera: dict[str, Cylinders]) -> Cylinders:
        """Every reporting camera's cylinders in site camera order, ``camera`` set to its index."""
        index = [i for i, c in enumerate(self.camera_ids) if c in per_camera]
        parts = [per_camera[self.camera_ids[i]] for i in index]
        seen = Cylinders.merge(parts)
        return replace(seen, camera=np.repeat(np.asarray(index, dtype=np.int64), [len(p) for p in parts]))

    def _fuse_left_over(self, views: Cylinders) -> Cylinders:
        """The people that views no track took place, fused without priors (``track_views`` births)."""
        # Not through this module's fuse_cylinders, which the tracking benchmark times as the
        # fusion stage: these fusions are part of the tracker's update.
        return fusion_rules.fuse_cylinders(views, self.cameras, self.site.thresholds.fusion_distance_m).fused

    def _cameras_of_views(self, table: TrackTable, input_cameras: np.ndarray) -> list[list[str]]:
        """For each track of ``table``, the ids of the cameras whose views it took this tick, in
        site camera order (``track_views``)."""
        keys = self.tracker.view_keys()
        took = keys >= 0
        by_key: dict[int, list[str]] = {}
        for key, camera in sorted(set(zip(keys[took].tolist(), input_cameras[took].tolist(), strict=True))):
            by_key.setdefault(key, []).append(self.camera_ids[camera])
        return [by_key.get(key, []) for key in table.key.tolist()]

    def _cameras_of_fused(self, fusion: Fusion, input_cameras: np.ndarray) -> list[list[str]]:
        """For each fused person, the ids of the cameras whose cylinders were merged into it, in
        site camera order."""
        fused_camera = fusion.fused.camera.tolist()
        # One camera's view alone (most people) names its camera; the rest are looked up.
        out = [self._alone[c] if c >= 0 else [] for c in fused_camera]
        merged = np.flatnonzero(fusion.assignment >= 0)  # not: off the floor, or a weak view alone
        shared = merged[fusion.fused.camera[fusion.assignment[merged]] < 0]
        count = len(self.camera_ids)
        person_camera = np.unique(fusion.assignment[shared] * count + input_cameras[shared])
        person = person_camera // count
        names = [self.camera_ids[c] for c in (person_camera % count).tolist()]
        starts = np.flatnonzero(np.diff(person, prepend=-1)).tolist()  # sorted: each person's run
        ends = starts[1:] + [len(names)] if starts else []
        for p, a, b in zip(person[starts].tolist(), starts, ends, strict=True):
            out[p] = names[a:b]
        return out
