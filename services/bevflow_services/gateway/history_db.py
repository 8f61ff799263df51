"""The gateway's history read from the database the recorder writes (``--db URL``).

``DatabaseHistory`` is a ``HistoryStore``: the routes read occupancy, alerts, trajectories and
contacts through it as they would from memory, and a restarted gateway serves the full history.
It writes nothing of the live stream: ``bevflow serve recorder --db URL`` does, and its ``add_*``
methods do nothing. Beyond the protocol it offers what only a database keeps: stepped occupancy
pages, track summaries and alert acknowledgements.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from bevflow.analytics.contacts import contacts
from bevflow.alert_lease import LEASE_S
from bevflow.analytics.trajectories import TrackHistory, Trajectory
from bevflow.capture_time import CaptureWindow
from bevflow.schemas import Contact, Event, Occupancy, Tracks
from bevflow.units import NS_PER_S

from bevflow_services.gateway.history import EventQuery, HistoryStore, InMemoryHistory, OccupancySample
from bevflow_services.runtime import UserError
from bevflow_services.storage import (
    Acknowledgement,
    EventFilter,
    HistoryDatabase,
    OccupancyPoint,
    RetentionPolicy,
    StorageError,
    TrackSummary,
)


def _sample(point: OccupancyPoint) -> OccupancySample:
    return OccupancySample(point.time_ns, point.total, point.zones)


class DatabaseHistory:
    """``HistoryStore`` over a ``HistoryDatabase``.

    ``occupancy()`` without ``since_ns`` returns the last ``open_range_s`` seconds (before
    ``until_ns`` or the newest sample) rather than the whole database: routes that read "all the
    history" were written for an hour in memory, not for a year on disk.

    Nothing is read beyond ``clock()`` plus the capture window's future bound
    (``bevflow.capture_time``): a row a forged message wrote there would otherwise head every
    newest-first list until the recorder's retention pass removes it.
    """

    def __init__(self, db: HistoryDatabase, open_range_s: float = 86_400.0, *,
                 clock: Callable[[], int] = time.time_ns, window: CaptureWindow | None = None) -> None:
        self.db = db
        self.open_range_ns = int(open_range_s * NS_PER_S)
        self.clock = clock
        self.window = window if window is not None else CaptureWindow.from_environment()

    def _until(self, until_ns: int | None) -> int:
        """``until_ns``, but no later than the newest capture time trusted now."""
        latest = self.window.latest_ns(self.clock())
        return latest if until_ns is None else min(until_ns, latest)

    @property
    def retention_ns(self) -> int:
        """How far back occupancy reaches: the recorder's retention (the default before one ran)."""
        policy = self.db.retention() or RetentionPolicy()
        return int(policy.occupancy_s * NS_PER_S)

    # --- the live stream: the recorder writes it ---------------------------------------------
    def add_occupancy(self, occupancy: Occupancy) -> None:
        pass

    def add_event(self, event: Event) -> None:
        pass

    def add_tracks(self, tracks: Tracks) -> None:
        pass

    # --- HistoryStore ----------------------------------------------------------------------------
    def occupancy(self, since_ns: int | None = None, until_ns: int | None = None) -> list[OccupancySample]:
        if since_ns is None:
            end = until_ns if until_ns is not None else self.db.newest_occupancy_ns(self._until(None))
            since_ns = None if end is None else end - self.open_range_ns
        return [_sample(p) for p in self.db.occupancy(since_ns, self._until(until_ns))]

    def events(self, query: EventQuery, limit: int, offset: int = 0) -> tuple[list[Event], int]:
        wanted = EventFilter(types=query.types, zone=query.zone, track=query.track, active=query.active,
                             since_ns=query.since_ns, until_ns=self._until(query.until_ns),
                             renewed_since_ns=self.clock() - int(LEASE_S * NS_PER_S))
        return self.db.events(wanted, limit, offset)

    def event(self, event_id: str) -> Event | None:
        """The newest state of one alert, None if the database does not hold it."""
        return self.db.event(event_id)

    def trajectory(self, track_id: int, since_ns: int | None = None, until_ns: int | None = None) -> Trajectory | None:
        path = self.db.trajectory(track_id, since_ns, self._until(until_ns))
        return None if path is None else Trajectory(track_id, path[0], path[1])

    def contacts(
        self, track_id: int, limit_m: float, since_ns: int | None = None, until_ns: int | None = None
    ) -> list[Contact] | None:
        path = self.db.trajectory(track_id)
        if path is None:
            return None
        times, xy = path
        if len(times) == 0:
            return []
        # Only the other tracks' samples that were close matter, so the database finds those and
        # the analytics code (the same as the in-memory history's) measures them.
        near = self.db.nearby_positions(track_id, limit_m, since_ns, until_ns)
        others = sorted({i for i, *_ in near})
        history = TrackHistory(max_points=len(times), sample_period_s=0.0, retire_after_s=1e9,
                               max_tracks=len(others) + 1)
        by_time: dict[int, list[tuple[int, float, float]]] = {}
        for other, t, x, y in near:
            by_time.setdefault(t, []).append((other, x, y))
        for t, (x, y) in zip(times.tolist(), xy.tolist(), strict=True):
            rows = [(track_id, x, y), *by_time.get(t, [])]
            history.update(t, [r[0] for r in rows], np.array([r[1:] for r in rows], dtype=np.float64))
        return contacts(history, track_id, limit_m, since_ns, until_ns)

    # --- what only the database keeps ------------------------------------------------------------
    def occupancy_steps(self, since_ns: int | None, until_ns: int | None, step_s: int, limit: int,
                        offset: int = 0) -> tuple[list[OccupancySample], int]:
        """Highest counts per ``step_s`` seconds, oldest first: one page and the number of steps."""
        points, total = self.db.occupancy_steps(since_ns, self._until(until_ns), step_s, limit, offset)
        return [_sample(p) for p in points], total

    def track_summaries(self, since_ns: int | None = None, until_ns: int | None = None, zone: str | None = None,
                        limit: int = 100, offset: int = 0) -> tuple[list[TrackSummary], int]:
        return self.db.track_summaries(since_ns, self._until(until_ns), zone, limit, offset)

    def acknowledge(self, event_id: str, user: str, time_ns: int, note: str = "") -> Acknowledgement:
        """Record who acknowledged an alert and when; KeyError for an alert not in the history."""
        return self.db.acknowledge(event_id, user, time_ns, note)

    def acknowledgements(self, event_id: str | None = None) -> list[Acknowledgement]:
        return self.db.acknowledgements(event_id)

    def close(self) -> None:
        self.db.close()


def history_store(db_url: str | None, history_s: float) -> HistoryStore:
    """The gateway's history: the database at ``db_url`` if given (``UserError`` if it cannot be
    opened), else ``history_s`` seconds in memory."""
    if not db_url:
        return InMemoryHistory(retention_s=history_s)
    try:
        return DatabaseHistory(HistoryDatabase.open(db_url))
    except StorageError as exc:
        raise UserError(f"--db: {exc}") from None
