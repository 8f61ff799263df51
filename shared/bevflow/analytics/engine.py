"""Every analytic of a site behind one call per tick, for the tracker service.

``SiteAnalytics.update`` checks the tick's positions, finds each person's zones once, and hands
them to the distance monitor (whose pair violations the incident tracker groups), the occupancy
counter, the crowded-interval trackers and the trajectory history. Crowded intervals are tracked for each zone with a crowded level
(``Zone.effective_crowded_level``) and for the site as a whole when it has a capacity
(``Site.crowded_level``, the same default share a zone uses).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

from numpy.typing import ArrayLike

from bevflow.analytics.contacts import contacts
from bevflow.analytics.distance import DistanceMonitor
from bevflow.analytics.incidents import IncidentTracker
from bevflow.analytics.intervals import CrowdedIntervalTracker
from bevflow.analytics.occupancy import OccupancyCounter
from bevflow.analytics.positions import IntArray, check_positions, seconds_to_ns
from bevflow.analytics.trajectories import TrackHistory, Trajectory
from bevflow.analytics.zones import BoolArray, ZoneIndex, zone_lists, zones_by_track
from bevflow.schemas import Contact, CrowdedInterval, DistanceIncident, DistanceViolation, Occupancy, OverCapacity
from bevflow.site import Site


@dataclass(frozen=True, eq=False)
class AnalyticsTick:
    """What one tick produced. ``events`` are ready to publish as they are: distance events (ends,
    then starts), the distance incidents they make up, then capacity events."""

    occupancy: Occupancy
    events: list[DistanceViolation | DistanceIncident | OverCapacity]
    violations: IntArray  # (K, 2) track-id pairs with an open distance violation, smaller id first
    ids: IntArray  # (N,) the tick's track ids, the rows of ``inside``
    inside: BoolArray  # (N, Z) person n stands in zone z
    zone_ids: tuple[str, ...]  # the columns of ``inside``
    intervals: list[CrowdedInterval] = field(default_factory=list)  # crowded intervals that ended

    @cached_property
    def zones_by_track(self) -> dict[int, list[str]]:
        """Track id -> the ids of the zones it stands in (built on first use)."""
        return zones_by_track(self.ids, self.inside, self.zone_ids)

    @cached_property
    def zones_by_row(self) -> list[list[str]]:
        """The ids of the zones each track stands in, in the order of ``ids`` (built on first use)."""
        return zone_lists(self.inside, self.zone_ids)


class SiteAnalytics:
    """Distance violations, occupancy, crowded intervals and trajectories of one site.

    ``release_margin_m`` is the distance hysteresis of ``DistanceMonitor``; ``crowded_gap_s`` and
    ``crowded_min_duration_s`` are the merge gap and minimum length of crowded intervals; the
    ``history_*`` options bound the trajectory store (``history_max_tracks=0`` turns it off).
    """

    def __init__(
        self,
        site: Site,
        release_margin_m: float = 0.2,
        crowded_gap_s: float = 30.0,
        crowded_min_duration_s: float = 60.0,
        history_period_s: float = 0.5,
        history_max_points: int = 600,
        history_max_tracks: int = 4096,
        history_retire_s: float = 600.0,
    ) -> None:
        self.site = site
        th = site.thresholds
        self.zones = ZoneIndex(site.zones)
        self.distance = DistanceMonitor(th, site.zones, release_margin_m=release_margin_m)
        self.incidents = IncidentTracker(th, site.zones)
        self.occupancy = OccupancyCounter(site.site, site.zones, th)
        gap, shortest = seconds_to_ns(crowded_gap_s), seconds_to_ns(crowded_min_duration_s)
        self.crowding: list[tuple[int, CrowdedIntervalTracker]] = []  # (zone column or -1 for the site, tracker)
        if site.crowded_level is not None:
            self.crowding.append((-1, CrowdedIntervalTracker(site.crowded_level, gap, shortest, zone=None)))
        for z, zone in enumerate(site.zones):
            if zone.effective_crowded_level is not None:
                self.crowding.append((z, CrowdedIntervalTracker(zone.effective_crowded_level, gap, shortest, zone.id)))
        self.history = (
            TrackHistory(history_max_points, history_period_s, history_retire_s, history_max_tracks)
            if history_max_tracks > 0
            else None
        )

    def update(self, time_ns: int, ids: ArrayLike, xy: ArrayLike, velocity: ArrayLike | None = None) -> AnalyticsTick:
        """Advance every analytic to ``time_ns`` with the site's active tracks, their feet positions
        and, when known, their (N, 2) velocities in m/s (they let the distance monitor tell a
        group walking together from strangers standing close).

        A tick with no tracks ends every open alert (what a service does at shutdown)."""
        ids_arr, xy_arr = check_positions(ids, xy)
        inside = self.zones.contains(xy_arr)
        distance_events = self.distance.update(time_ns, ids_arr, xy_arr, velocity)
        events: list[DistanceViolation | DistanceIncident | OverCapacity] = list(distance_events)
        events += self.incidents.update(time_ns, self.distance.current_pairs, ids_arr, xy_arr)
        occupancy, capacity_events = self.occupancy.update(time_ns, ids_arr, xy_arr, inside=inside)
        events += capacity_events
        zone_counts = [z.count for z in occupancy.zones]
        intervals = []
        for column, tracker in self.crowding:
            finished = tracker.update(time_ns, occupancy.total if column < 0 else zone_counts[column])
            if finished is not None:
                intervals.append(finished)
        if self.history is not None:
            self.history.update(time_ns, ids_arr, xy_arr)
        return AnalyticsTick(
            occupancy=occupancy,
            events=events,
            violations=self.distance.current_pairs,
            ids=ids_arr,
            inside=inside,
            zone_ids=self.zones.ids,
            intervals=intervals,
        )

    @property
    def crowded_now(self) -> list[CrowdedInterval]:
        """Crowded intervals in progress (``end_ns`` None)."""
        return [i for _, tracker in self.crowding if (i := tracker.current) is not None]

    def trajectory(self, track_id: int) -> Trajectory:
        """The stored trajectory of a track; KeyError if there is none (or history is off)."""
        if self.history is None:
            raise KeyError("trajectory history is turned off")
        return self.history.trajectory(track_id)

    def contacts(self, track_id: int, limit_m: float | None = None) -> list[Contact]:
        """Who came closer than ``limit_m`` (default: the social distance) to a track."""
        if self.history is None:
            raise KeyError("trajectory history is turned off")
        limit = self.site.thresholds.social_distance_m if limit_m is None else limit_m
        return contacts(self.history, track_id, limit)
