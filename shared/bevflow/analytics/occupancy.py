"""People counts per zone and for the whole site, and over-capacity alerts (paper 3.8).

The site count is the number of active tracks at the tick (the paper's rule); a zone's count is the
number of those whose feet stand in its polygon (edge rule in ``bevflow.analytics.zones``).

Over capacity starts once the count has been > capacity at every tick for
``capacity_min_duration_s`` (default 0: at the first such tick; ``start_ns`` is that first tick)
and ends at the first tick with count <= max(capacity - capacity_hysteresis, 0). A crowd hovering
at the limit (49, 50, 51, 50, 51, ...) therefore raises one alert, not one per step. ``peak`` is the highest count seen during
the alert: the start event carries the count that started it, the end event the final peak.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from numpy.typing import ArrayLike

from bevflow.analytics.positions import Clock, check_positions, seconds_to_ns
from bevflow.analytics.zones import BoolArray, ZoneIndex
from bevflow.schemas import Occupancy, OverCapacity, ZoneOccupancy
from bevflow.site import Thresholds, Zone


@dataclass
class _CapacityAlarm:
    """The hysteresis state of one capacity limit (a zone's, or the site's when ``zone`` is None)."""

    zone: str | None
    capacity: int
    release: int
    min_duration_ns: int = 0
    start_ns: int | None = None
    peak: int = 0
    over_since: int | None = None  # first tick of the current stretch over capacity, before the alert starts

    def step(self, t: int, count: int) -> OverCapacity | None:
        if self.start_ns is None:
            if count <= self.capacity:
                self.over_since = None
                return None
            self.over_since = t if self.over_since is None else self.over_since
            self.peak = count if self.over_since == t else max(self.peak, count)
            if t - self.over_since < self.min_duration_ns:
                return None
            self.start_ns, self.over_since = self.over_since, None
            return self.as_event(None, t)
        self.peak = max(self.peak, count)
        if count > self.release:
            return None
        event = self.as_event(t, t)
        self.start_ns = None
        return event

    def as_event(self, end_ns: int | None, raised_ns: int) -> OverCapacity:
        assert self.start_ns is not None
        return OverCapacity(
            id=f"capacity-{self.zone or 'site'}-{self.start_ns}",
            start_ns=self.start_ns,
            end_ns=end_ns,
            zone=self.zone,
            capacity=self.capacity,
            peak=self.peak,
            raised_ns=raised_ns,
        )


class OccupancyCounter:
    """Counts people per zone and site at each tick, and raises ``OverCapacity`` start/end events.

    >>> from bevflow.site import Thresholds
    >>> counter = OccupancyCounter("hall", [], Thresholds(site_capacity=1, capacity_hysteresis=0))
    >>> occupancy, events = counter.update(0, [7, 8], [[0, 0], [5, 5]])
    >>> occupancy.total, [(e.peak, e.end_ns) for e in events]
    (2, [(2, None)])
    """

    def __init__(self, site_name: str, zones: Sequence[Zone], thresholds: Thresholds) -> None:
        self.site_name = site_name
        self.zones = ZoneIndex(zones)
        self.site_capacity = thresholds.site_capacity
        hysteresis = thresholds.capacity_hysteresis
        self._alarms: list[tuple[int, _CapacityAlarm]] = []  # (zone column or -1 for the site, alarm)
        limits = [(-1, None, thresholds.site_capacity)] + [(z, zone.id, zone.capacity) for z, zone in enumerate(zones)]
        for column, zone_id, capacity in limits:
            if capacity is not None:
                alarm = _CapacityAlarm(zone=zone_id, capacity=capacity, release=max(capacity - hysteresis, 0),
                                       min_duration_ns=seconds_to_ns(thresholds.capacity_min_duration_s))
                self._alarms.append((column, alarm))
        self._clock = Clock()

    def update(
        self, time_ns: int, ids: ArrayLike, xy: ArrayLike, inside: BoolArray | None = None
    ) -> tuple[Occupancy, list[OverCapacity]]:
        """Counts at ``time_ns`` and the capacity events that started or ended then.

        ``inside`` is the (N, Z) zone membership of the tracks when the caller already has it."""
        ids_arr, xy_arr = check_positions(ids, xy)
        if inside is None:
            inside = self.zones.contains(xy_arr)
        elif inside.shape != (len(ids_arr), len(self.zones)):
            raise ValueError(f"membership matrix has shape {inside.shape}, expected {(len(ids_arr), len(self.zones))}")
        t = self._clock.advance(time_ns)
        counts = inside.sum(axis=0).tolist()
        total = len(ids_arr)
        occupancy = Occupancy(
            site=self.site_name,
            time_ns=t,
            total=total,
            capacity=self.site_capacity,
            zones=[
                ZoneOccupancy(id=z.id, name=z.name, count=c, capacity=z.capacity)
                for z, c in zip(self.zones.zones, counts, strict=True)
            ],
        )
        events = []
        for column, alarm in self._alarms:
            event = alarm.step(t, total if column < 0 else counts[column])
            if event is not None:
                events.append(event)
        return occupancy, events

    @property
    def open_alerts(self) -> list[OverCapacity]:
        """The over-capacity alerts open now, as their start messages with the peak so far."""
        return [alarm.as_event(None, alarm.start_ns) for _, alarm in self._alarms if alarm.start_ns is not None]
