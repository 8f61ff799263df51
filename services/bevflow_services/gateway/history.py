"""What the gateway remembers: occupancy over time, alerts, and each track's path.

The routes read history only through ``HistoryStore``, so a database-backed store can replace the
in-memory one without touching them. ``InMemoryHistory`` keeps a bounded window (an hour by
default) and is safe to call from several threads.
"""

from __future__ import annotations

import bisect
import threading
from collections import OrderedDict, deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bevflow.analytics.contacts import contacts
from bevflow.analytics.trajectories import TrackHistory, Trajectory
from bevflow.schemas import Contact, Event, Occupancy, Tracks
from bevflow.units import NS_PER_S


@dataclass(frozen=True)
class OccupancySample:
    """Occupancy over one second: the highest count seen in it, site-wide and per zone.

    The maximum rather than the mean, so a short peak over capacity still shows in the history.
    Treat ``zones`` as read-only: samples are shared, not copied, by ``occupancy()``.
    """

    time_ns: int
    total: int
    zones: dict[str, int]


@dataclass(frozen=True)
class EventQuery:
    """Which alerts to list. An alert matches the time range when it overlaps it."""

    types: frozenset[str] | None = None
    zone: str | None = None
    track: int | None = None
    active: bool | None = None
    since_ns: int | None = None
    until_ns: int | None = None

    def matches(self, event: Event) -> bool:
        if self.types is not None and event.type not in self.types:
            return False
        if self.zone is not None and event.zone != self.zone:
            return False
        if self.track is not None and self.track not in event.tracks:
            return False
        if self.active is not None and (event.end_ns is None) != self.active:
            return False
        if self.until_ns is not None and event.start_ns > self.until_ns:
            return False
        return self.since_ns is None or event.end_ns is None or event.end_ns >= self.since_ns


class HistoryStore(Protocol):
    """The history the REST routes query. Times are capture times in nanoseconds."""

    def add_occupancy(self, occupancy: Occupancy) -> None: ...

    def occupancy(self, since_ns: int | None = None, until_ns: int | None = None) -> list[OccupancySample]:
        """One sample per second, oldest first, within [since_ns, until_ns]."""
        ...

    def add_event(self, event: Event) -> None:
        """Store an alert; a later message with the same ``id`` (its end) replaces it."""
        ...

    def events(self, query: EventQuery, limit: int, offset: int = 0) -> tuple[list[Event], int]:
        """Matching alerts newest first (by start), one page of them, and how many match in all."""
        ...

    def event(self, event_id: str) -> Event | None:
        """The newest state of one alert, None if it is not (or no longer) kept."""
        ...

    def add_tracks(self, tracks: Tracks) -> None:
        """Record a tick's track positions (ticks must come in time order)."""
        ...

    def trajectory(self, track_id: int, since_ns: int | None = None, until_ns: int | None = None) -> Trajectory | None:
        """A track's stored path within [since_ns, until_ns], or None if the track is not remembered."""
        ...

    def contacts(
        self, track_id: int, limit_m: float, since_ns: int | None = None, until_ns: int | None = None
    ) -> list[Contact] | None:
        """Tracks that came closer than ``limit_m`` to ``track_id``; None if it is not remembered."""
        ...


class InMemoryHistory:
    """``HistoryStore`` in memory, keeping the last ``retention_s`` seconds of capture time.

    Alerts are also capped in number (``max_events``, oldest dropped first) so a flood of short
    violations cannot exhaust memory.
    """

    def __init__(
        self,
        retention_s: float = 3600.0,
        max_events: int = 10_000,
        track_period_s: float = 1.0,
        track_max_points: int = 1800,
        max_tracks: int = 4096,
    ) -> None:
        if retention_s <= 0:
            raise ValueError(f"retention_s must be positive, got {retention_s}")
        self.retention_ns = int(retention_s * NS_PER_S)
        self.max_events = max_events
        self._lock = threading.Lock()
        self._seconds: deque[OccupancySample] = deque()  # the newest one may still grow
        self._events: OrderedDict[str, Event] = OrderedDict()
        # Tracks: one sample per track per period; a track unseen for the retention time is forgotten.
        self._tracks = TrackHistory(track_max_points, track_period_s, retention_s, max_tracks)

    # --- occupancy -----------------------------------------------------------------------------
    def add_occupancy(self, occupancy: Occupancy) -> None:
        start_ns = occupancy.time_ns // NS_PER_S * NS_PER_S
        zones = {z.id: z.count for z in occupancy.zones}
        with self._lock:
            last = self._seconds[-1] if self._seconds else None
            if last is not None and start_ns < last.time_ns:
                return  # late message for a second already closed: the bucket would reopen out of order
            if last is not None and start_ns == last.time_ns:
                merged = {z: max(c, zones.get(z, 0)) for z, c in last.zones.items()} | {
                    z: c for z, c in zones.items() if z not in last.zones
                }
                self._seconds[-1] = OccupancySample(start_ns, max(last.total, occupancy.total), merged)
            else:
                self._seconds.append(OccupancySample(start_ns, occupancy.total, zones))
            while self._seconds and self._seconds[0].time_ns < start_ns - self.retention_ns:
                self._seconds.popleft()

    def occupancy(self, since_ns: int | None = None, until_ns: int | None = None) -> list[OccupancySample]:
        with self._lock:
            samples = list(self._seconds)
        lo = 0 if since_ns is None else bisect.bisect_left(samples, since_ns, key=lambda s: s.time_ns)
        hi = len(samples) if until_ns is None else bisect.bisect_right(samples, until_ns, key=lambda s: s.time_ns)
        return samples[lo:hi]

    # --- alerts --------------------------------------------------------------------------------
    def add_event(self, event: Event) -> None:
        with self._lock:
            self._events[event.id] = event
            horizon = event.start_ns - self.retention_ns
            while self._events:
                oldest = next(iter(self._events.values()))
                too_many = len(self._events) > self.max_events
                expired = oldest.end_ns is not None and oldest.end_ns < horizon
                if not (too_many or expired):
                    break
                self._events.popitem(last=False)

    def event(self, event_id: str) -> Event | None:
        """The newest state of one alert, None if it is not (or no longer) kept."""
        with self._lock:
            return self._events.get(event_id)

    def events(self, query: EventQuery, limit: int, offset: int = 0) -> tuple[list[Event], int]:
        with self._lock:
            stored = list(self._events.values())
        matching = sorted((e for e in stored if query.matches(e)), key=lambda e: (e.start_ns, e.id), reverse=True)
        return matching[offset : offset + limit], len(matching)

    # --- tracks --------------------------------------------------------------------------------
    def add_tracks(self, tracks: Tracks) -> None:
        ids = [t.id for t in tracks.tracks]
        xy = [t.xy for t in tracks.tracks]
        with self._lock:
            self._tracks.update(tracks.time_ns, ids, xy)

    def trajectory(self, track_id: int, since_ns: int | None = None, until_ns: int | None = None) -> Trajectory | None:
        with self._lock:
            if track_id not in self._tracks:
                return None
            path = self._tracks.trajectory(track_id)
        keep = np.ones(len(path), dtype=bool)
        if since_ns is not None:
            keep &= path.times_ns >= since_ns
        if until_ns is not None:
            keep &= path.times_ns <= until_ns
        return Trajectory(path.track_id, path.times_ns[keep], path.xy[keep])

    def contacts(
        self, track_id: int, limit_m: float, since_ns: int | None = None, until_ns: int | None = None
    ) -> list[Contact] | None:
        with self._lock:
            if track_id not in self._tracks:
                return None
            return contacts(self._tracks, track_id, limit_m, since_ns, until_ns)
