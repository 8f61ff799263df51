"""Writes gathered between two commits, already reduced to the rows they will become.

Everything in a ``Batch`` is idempotent to write, so a batch that failed can be merged into the
next one and written again, and replayed alerts can be written twice:

- occupancy: the highest count per (second, zone); writing keeps the higher of stored and new;
- alerts: the latest state per id; an end (``end_ns`` set) is final and a start never replaces it;
- renewals: ids of open alerts the tracker still has open, whose lease restarts when written;
- track positions: one per (track, time); writing an existing one changes nothing.

``TrackSampler`` decides which tracker ticks become stored positions: the first tick of each
sampling period, for every track present, as ``bevflow.analytics.trajectories.TrackHistory``
does, so every track's samples share timestamps and contacts compare them without interpolating.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

from bevflow.schemas import Event, Occupancy, Tracks
from bevflow.units import NS_PER_S

from bevflow_services.storage.records import SITE

K = TypeVar("K")
V = TypeVar("V")


def _later_state(stored: Event | None, new: Event) -> Event:
    """Which of two messages with the same alert id to keep: an end beats a start."""
    if stored is None or (stored.end_ns is None and new.end_ns is not None):
        return new
    if stored.end_ns is not None and new.end_ns is None:
        return stored
    return new


@dataclass
class Batch:
    """Rows waiting to be written (see the module docstring)."""

    occupancy: dict[tuple[int, str], int] = field(default_factory=dict)
    events: dict[str, Event] = field(default_factory=dict)
    points: dict[tuple[int, int], tuple[float, float]] = field(default_factory=dict)
    tracks: dict[int, tuple[int, int]] = field(default_factory=dict)
    track_zones: dict[tuple[int, str], tuple[int, int]] = field(default_factory=dict)
    renewals: set[str] = field(default_factory=set)

    def __len__(self) -> int:
        return len(self.occupancy) + len(self.events) + len(self.points) + len(self.renewals)

    def add_occupancy(self, occupancy: Occupancy) -> None:
        second = occupancy.time_ns // NS_PER_S * NS_PER_S
        counts = [(SITE, occupancy.total), *((z.id, z.count) for z in occupancy.zones)]
        for zone, count in counts:
            key = (second, zone)
            self.occupancy[key] = max(count, self.occupancy.get(key, count))

    def add_event(self, event: Event) -> None:
        self.events[event.id] = _later_state(self.events.get(event.id), event)

    def add_track_sample(self, tracks: Tracks) -> None:
        """Store every track of this tick (call only for the ticks a ``TrackSampler`` keeps)."""
        t = tracks.time_ns
        for track in tracks.tracks:
            self.points[(track.id, t)] = (float(track.xy[0]), float(track.xy[1]))
            _widen(self.tracks, track.id, t, t)
            for zone in track.zones:
                _widen(self.track_zones, (track.id, zone), t, t)

    def merge(self, newer: Batch) -> None:
        """Add ``newer``'s rows to these (this batch being the older one)."""
        for key, count in newer.occupancy.items():
            self.occupancy[key] = max(count, self.occupancy.get(key, count))
        for event in newer.events.values():
            self.add_event(event)
        self.points.update(newer.points)
        for track_id, (first, last) in newer.tracks.items():
            _widen(self.tracks, track_id, first, last)
        for key, (first, last) in newer.track_zones.items():
            _widen(self.track_zones, key, first, last)
        self.renewals |= newer.renewals

    def drop_oldest_samples(self, keep: int) -> int:
        """Keep at most ``keep`` occupancy rows and as many positions, dropping the oldest; alerts
        are never dropped. For a database that stays down: memory must not grow without bound.
        Returns how many rows were dropped."""
        return _drop_oldest(self.occupancy, keep, lambda k: k[0]) + _drop_oldest(self.points, keep, lambda k: k[1])


def _widen(table: dict, key: object, first: int, last: int) -> None:
    old = table.get(key)
    table[key] = (first, last) if old is None else (min(old[0], first), max(old[1], last))


class TrackSampler:
    """Keeps the first tick of every ``period_s`` of capture time (and any tick after a gap)."""

    def __init__(self, period_s: float = 1.0, last_sampled_ns: int | None = None) -> None:
        if period_s <= 0:
            raise ValueError(f"period_s must be positive, got {period_s}")
        self.period_ns = int(period_s * NS_PER_S)
        self._last_bucket = None if last_sampled_ns is None else last_sampled_ns // self.period_ns

    def keep(self, time_ns: int) -> bool:
        bucket = time_ns // self.period_ns
        if self._last_bucket is not None and bucket <= self._last_bucket:
            return False
        self._last_bucket = bucket
        return True


def _drop_oldest(table: dict[K, V], keep: int, time_of: Callable[[K], int]) -> int:
    """Drop all but the ``keep`` latest rows of ``table``; how many went."""
    extra = len(table) - keep
    if extra <= 0:
        return 0
    for key in sorted(table, key=time_of)[:extra]:
        del table[key]
    return extra
