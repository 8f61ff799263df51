"""``HistoryDatabase``: the site's history in SQLite or PostgreSQL, written in batches, read by
range and page.

>>> db = HistoryDatabase.open(":memory:")                     # doctest: +SKIP
>>> db.write(batch); db.events(EventFilter(active=True), 10)   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from bevflow.schemas import Event, decode_event

from bevflow_services.storage.backend import Transaction
from bevflow_services.storage.database import Database
from bevflow_services.storage.batch import Batch
from bevflow_services.storage.records import (
    SITE,
    Acknowledgement,
    EventFilter,
    OccupancyPoint,
    RetentionPolicy,
    RetentionResult,
    TrackSummary,
    ZoneVisit,
)
from bevflow_services.storage.retention import apply_retention

KEEP_HIGHER = "CASE WHEN excluded.{c} > {t}.{c} THEN excluded.{c} ELSE {t}.{c} END"
KEEP_LOWER = "CASE WHEN excluded.{c} < {t}.{c} THEN excluded.{c} ELSE {t}.{c} END"

UPSERT_OCCUPANCY = ("INSERT INTO occupancy (time_ns, zone, people) VALUES (?, ?, ?) ON CONFLICT (time_ns, zone) "
                    "DO UPDATE SET people = " + KEEP_HIGHER.format(c="people", t="occupancy"))
# An alert row changes only while it is active (an incident's people change, then it ends): a
# replayed start never reopens an ended alert.
UPSERT_EVENT = (
    "INSERT INTO events (id, type, zone, start_ns, end_ns, body, recorded_ns) VALUES (?, ?, ?, ?, ?, ?, ?) "
    "ON CONFLICT (id) DO UPDATE SET zone = excluded.zone, end_ns = excluded.end_ns, body = excluded.body, "
    "recorded_ns = excluded.recorded_ns WHERE events.end_ns IS NULL"
)
# A renewal (``OpenAlerts``) restarts an open alert's lease: ``recorded_ns`` is when its row was
# last written or renewed.
RENEW_EVENT = "UPDATE events SET recorded_ns = ? WHERE id = ? AND end_ns IS NULL"
INSERT_EVENT_TRACK = "INSERT INTO event_tracks (track_id, event_id) VALUES (?, ?) ON CONFLICT DO NOTHING"
INSERT_POINT = "INSERT INTO track_points (track_id, time_ns, x, y) VALUES (?, ?, ?, ?) ON CONFLICT DO NOTHING"
UPSERT_TRACK = (
    "INSERT INTO tracks (track_id, first_ns, last_ns) VALUES (?, ?, ?) ON CONFLICT (track_id) DO UPDATE SET "
    f"first_ns = {KEEP_LOWER.format(c='first_ns', t='tracks')}, last_ns = {KEEP_HIGHER.format(c='last_ns', t='tracks')}"
)
UPSERT_TRACK_ZONE = (
    "INSERT INTO track_zones (track_id, zone, first_ns, last_ns) VALUES (?, ?, ?, ?) ON CONFLICT (track_id, zone) "
    f"DO UPDATE SET first_ns = {KEEP_LOWER.format(c='first_ns', t='track_zones')}, "
    f"last_ns = {KEEP_HIGHER.format(c='last_ns', t='track_zones')}"
)


INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1


def int64(value: int) -> int:
    """``value`` clamped to what both databases store: a time or id beyond it matches nothing
    there anyway, and must not overflow the driver."""
    return min(max(int(value), INT64_MIN), INT64_MAX)


def between(column: str, since_ns: int | None, until_ns: int | None) -> tuple[list[str], list[int]]:
    """SQL conditions (and their parameters) for ``since_ns <= column <= until_ns``."""
    where, params = [], []
    if since_ns is not None:
        where.append(f"{column} >= ?")
        params.append(int64(since_ns))
    if until_ns is not None:
        where.append(f"{column} <= ?")
        params.append(int64(until_ns))
    return where, params


def _where(conditions: Sequence[str]) -> str:
    return " WHERE " + " AND ".join(conditions) if conditions else ""


class HistoryDatabase(Database):
    """One site's history (tables in ``bevflow_services.storage.schema``), behind a ``Backend``.

    Safe to share between threads. Several processes may open the same database: the recorder
    writes, the gateway reads and records acknowledgements.
    """

    # --- writing -------------------------------------------------------------------------------
    def write(self, batch: Batch, recorded_ns: int | None = None) -> None:
        """Write a batch in one transaction: all of it or, on an exception, none of it."""
        recorded = time.time_ns() if recorded_ns is None else recorded_ns
        with self.backend.transaction() as tx:
            tx.executemany(UPSERT_OCCUPANCY, [(t, z, c) for (t, z), c in sorted(batch.occupancy.items())])
            self._write_events(tx, list(batch.events.values()), recorded)
            tx.executemany(INSERT_POINT, [(i, t, x, y) for (i, t), (x, y) in sorted(batch.points.items())])
            tx.executemany(UPSERT_TRACK, [(i, a, b) for i, (a, b) in sorted(batch.tracks.items())])
            tx.executemany(UPSERT_TRACK_ZONE, [(i, z, a, b) for (i, z), (a, b) in sorted(batch.track_zones.items())])
            tx.executemany(RENEW_EVENT, [(recorded, i) for i in sorted(batch.renewals)])

    @staticmethod
    def _write_events(tx: Transaction, events: list[Event], recorded_ns: int) -> None:
        tx.executemany(UPSERT_EVENT, [
            (e.id, e.type, e.zone, e.start_ns, e.end_ns, e.model_dump_json(), recorded_ns) for e in events])
        tx.executemany(INSERT_EVENT_TRACK, [(t, e.id) for e in events for t in sorted(set(e.tracks))])

    # --- occupancy -----------------------------------------------------------------------------
    def _samples_sql(self, since_ns: int | None, until_ns: int | None) -> tuple[str, list[int]]:
        """A derived table (time_ns, zone, people) of fine and coarse occupancy in the range."""
        fine, fine_params = between("time_ns", since_ns, until_ns)
        coarse, coarse_params = between("time_ns", since_ns, until_ns)
        sql = (f"(SELECT time_ns, zone, people FROM occupancy{_where(fine)} UNION ALL "
               f"SELECT time_ns, zone, max_people FROM occupancy_coarse{_where(coarse)}) AS samples")
        return sql, fine_params + coarse_params

    def occupancy(self, since_ns: int | None = None, until_ns: int | None = None) -> list[OccupancyPoint]:
        """Occupancy at the resolution stored, oldest first: a point per second for recent data,
        per coarse step (``step_s``) beyond the fine retention window."""
        fine, params = between("time_ns", since_ns, until_ns)
        rows = self.backend.query(
            f"SELECT time_ns, 1, zone, people FROM occupancy{_where(fine)} UNION ALL "
            f"SELECT time_ns, step_s, zone, max_people FROM occupancy_coarse{_where(fine)} ORDER BY 1",
            params + params)
        return _pivot(rows)

    def newest_occupancy_ns(self, until_ns: int | None = None) -> int | None:
        """Time of the newest stored occupancy sample no later than ``until_ns``; None for an empty history."""
        where, params = between("time_ns", None, until_ns)
        rows = self.backend.query(f"SELECT MAX(time_ns) FROM occupancy{_where(where)} UNION ALL "
                                  f"SELECT MAX(time_ns) FROM occupancy_coarse{_where(where)}", params + params)
        times = [int(t) for (t,) in rows if t is not None]
        return max(times) if times else None

    def occupancy_steps(self, since_ns: int | None, until_ns: int | None, step_s: int, limit: int,
                        offset: int = 0) -> tuple[list[OccupancyPoint], int]:
        """The highest counts per ``step_s`` seconds (aligned to the Unix epoch), oldest first:
        one page, and how many steps hold data in all."""
        if step_s < 1 or limit < 1 or offset < 0:
            raise ValueError(f"step_s and limit must be >= 1 and offset >= 0, got {step_s}, {limit}, {offset}")
        step_ns = int(step_s) * 1_000_000_000
        samples, params = self._samples_sql(since_ns, until_ns)
        (total,), = self.backend.query(f"SELECT COUNT(DISTINCT time_ns / ?) FROM {samples}", [step_ns, *params])
        buckets = self.backend.query(f"SELECT DISTINCT time_ns / ? FROM {samples} ORDER BY 1 LIMIT ? OFFSET ?",
                                     [step_ns, *params, int64(limit), int64(offset)])
        if not buckets:
            return [], int(total)
        lo = max(int(buckets[0][0]) * step_ns, since_ns if since_ns is not None else 0)
        hi = (int(buckets[-1][0]) + 1) * step_ns - 1
        hi = hi if until_ns is None else min(hi, until_ns)
        samples, params = self._samples_sql(lo, hi)
        rows = self.backend.query(
            f"SELECT time_ns / ? * ?, ?, zone, MAX(people) FROM {samples} GROUP BY 1, 3 ORDER BY 1",
            [step_ns, step_ns, step_s, *params])
        return _pivot(rows), int(total)

    # --- alerts --------------------------------------------------------------------------------
    def events(self, query: EventFilter, limit: int, offset: int = 0) -> tuple[list[Event], int]:
        """Matching alerts newest first (by start, then id), one page, and how many match in all."""
        where: list[str] = []
        params: list[Any] = []
        if query.types is not None:
            where.append(f"type IN ({', '.join('?' * len(query.types))})" if query.types else "1 = 0")
            params.extend(sorted(query.types))
        if query.zone is not None:
            where.append("zone = ?")
            params.append(query.zone)
        if query.track is not None:
            where.append("id IN (SELECT event_id FROM event_tracks WHERE track_id = ?)")
            params.append(int64(query.track))
        lapsed = None if query.renewed_since_ns is None else int64(query.renewed_since_ns)
        if query.active is not None and lapsed is None:
            where.append("end_ns IS NULL" if query.active else "end_ns IS NOT NULL")
        elif query.active is not None:
            where.append("(end_ns IS NULL AND recorded_ns >= ?)" if query.active else "(end_ns IS NOT NULL OR recorded_ns < ?)")
            params.append(lapsed)
        if query.until_ns is not None:
            where.append("start_ns <= ?")
            params.append(int64(query.until_ns))
        if query.since_ns is not None:
            where.append("(end_ns IS NULL OR end_ns >= ?)")
            params.append(int64(query.since_ns))
        (total,), = self.backend.query(f"SELECT COUNT(*) FROM events{_where(where)}", params)
        rows = self.backend.query(
            f"SELECT body, end_ns, recorded_ns FROM events{_where(where)} ORDER BY start_ns DESC, id DESC LIMIT ? OFFSET ?",
            [*params, int64(limit), int64(offset)])
        events = [_lapsed(decode_event(body), recorded) if end is None and lapsed is not None and recorded < lapsed
                  else decode_event(body) for body, end, recorded in rows]
        return events, int(total)

    def end_lapsed_events(self, renewed_before_ns: int) -> int:
        """End the open alerts not written nor renewed since ``renewed_before_ns``, each at its last
        renewal (``bevflow.alert_lease``); returns how many ended."""
        with self.backend.transaction() as tx:
            rows = tx.execute("SELECT body, recorded_ns FROM events WHERE end_ns IS NULL AND recorded_ns < ?",
                              [int64(renewed_before_ns)])
            ended = [_lapsed(decode_event(body), int(recorded)) for body, recorded in rows]
            tx.executemany("UPDATE events SET end_ns = ?, body = ? WHERE id = ? AND end_ns IS NULL",
                           [(e.end_ns, e.model_dump_json(), e.id) for e in ended])
        return len(ended)

    def event(self, event_id: str) -> Event | None:
        rows = self.backend.query("SELECT body FROM events WHERE id = ?", [event_id])
        return decode_event(rows[0][0]) if rows else None

    # --- tracks --------------------------------------------------------------------------------
    def track_summaries(self, since_ns: int | None = None, until_ns: int | None = None, zone: str | None = None,
                        limit: int = 100, offset: int = 0) -> tuple[list[TrackSummary], int]:
        """Tracks seen within [since_ns, until_ns] (in ``zone`` if given), newest first (by first
        sighting, then id): one page, and how many match in all."""
        lower, lower_params = between("t.last_ns", since_ns, None)
        upper, upper_params = between("t.first_ns", None, until_ns)
        where, params = lower + upper, list[int | str]([*lower_params, *upper_params])
        if zone is not None:
            where.append("t.track_id IN (SELECT track_id FROM track_zones WHERE zone = ?)")
            params.append(zone)
        (total,), = self.backend.query(f"SELECT COUNT(*) FROM tracks t{_where(where)}", params)
        rows = self.backend.query(
            f"SELECT t.track_id, t.first_ns, t.last_ns, (SELECT COUNT(*) FROM track_points p WHERE p.track_id = t.track_id) "
            f"FROM tracks t{_where(where)} ORDER BY t.first_ns DESC, t.track_id DESC LIMIT ? OFFSET ?",
            [*params, int64(limit), int64(offset)])
        visits: dict[int, list[ZoneVisit]] = {int(r[0]): [] for r in rows}
        if visits:
            ids = sorted(visits)
            for track_id, zone_id, first, last in self.backend.query(
                    f"SELECT track_id, zone, first_ns, last_ns FROM track_zones WHERE track_id IN ({', '.join('?' * len(ids))}) "
                    "ORDER BY track_id, first_ns, zone", ids):
                visits[int(track_id)].append(ZoneVisit(str(zone_id), int(first), int(last)))
        summaries = [TrackSummary(int(i), int(a), int(b), int(n), visits[int(i)]) for i, a, b, n in rows]
        return summaries, int(total)

    def trajectory(self, track_id: int, since_ns: int | None = None,
                   until_ns: int | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """A track's stored positions in the range, oldest first: times (K,) int64 and xy (K, 2);
        None when the database has no such track."""
        if not self.backend.query("SELECT 1 FROM tracks WHERE track_id = ?", [int64(track_id)]):
            return None
        where, params = between("time_ns", since_ns, until_ns)
        rows = self.backend.query(
            f"SELECT time_ns, x, y FROM track_points WHERE track_id = ?{''.join(' AND ' + w for w in where)} ORDER BY time_ns",
            [int64(track_id), *params])
        times = np.array([r[0] for r in rows], dtype=np.int64)
        xy = np.array([(r[1], r[2]) for r in rows], dtype=np.float64).reshape(-1, 2)
        return times, xy

    def nearby_positions(self, track_id: int, limit_m: float, since_ns: int | None = None,
                         until_ns: int | None = None) -> list[tuple[int, int, float, float]]:
        """Other tracks' positions (track id, time, x, y) closer than ``limit_m`` to ``track_id``'s
        position of the same sample time, oldest first: what contact tracing needs, found by the
        database rather than by loading everyone's path."""
        where, params = between("t.time_ns", since_ns, until_ns)
        rows = self.backend.query(
            "SELECT o.track_id, o.time_ns, o.x, o.y FROM track_points t JOIN track_points o ON o.time_ns = t.time_ns "
            "WHERE t.track_id = ? AND o.track_id <> ? AND (o.x - t.x) * (o.x - t.x) + (o.y - t.y) * (o.y - t.y) < ?"
            f"{''.join(' AND ' + w for w in where)} ORDER BY o.time_ns, o.track_id",
            [int64(track_id), int64(track_id), float(limit_m) ** 2, *params])
        return [(int(i), int(t), float(x), float(y)) for i, t, x, y in rows]

    def newest_track_time_ns(self, until_ns: int | None = None) -> int | None:
        """Capture time of the newest stored position no later than ``until_ns`` (where a restarted
        recorder resumes sampling: a row beyond its clock must not stop it for good)."""
        where, params = between("time_ns", None, until_ns)
        (newest,), = self.backend.query(f"SELECT MAX(time_ns) FROM track_points{_where(where)}", params)
        return None if newest is None else int(newest)

    # --- acknowledgements ----------------------------------------------------------------------
    def acknowledge(self, event_id: str, user: str, time_ns: int, note: str = "") -> Acknowledgement:
        """Record that ``user`` acknowledged alert ``event_id`` at ``time_ns``; KeyError if the
        database has no such alert. Every acknowledgement is kept (several people may)."""
        if not user.strip():
            raise ValueError("an acknowledgement needs the user's name")
        with self.backend.transaction() as tx:
            if not tx.execute("SELECT 1 FROM events WHERE id = ?", [event_id]):
                raise KeyError(f"no alert {event_id!r} in the history")
            (ack_id,), = tx.execute(
                "INSERT INTO acknowledgements (event_id, user_name, time_ns, note) VALUES (?, ?, ?, ?) RETURNING id",
                [event_id, user, int(time_ns), note])
        return Acknowledgement(int(ack_id), event_id, user, int(time_ns), note)

    def acknowledgements(self, event_id: str | None = None) -> list[Acknowledgement]:
        """Acknowledgements of one alert (or of all), oldest first."""
        where, params = (["event_id = ?"], [event_id]) if event_id is not None else ([], [])
        rows = self.backend.query(
            f"SELECT id, event_id, user_name, time_ns, note FROM acknowledgements{_where(where)} ORDER BY time_ns, id",
            params)
        return [Acknowledgement(int(i), str(e), str(u), int(t), str(n)) for i, e, u, t, n in rows]

    # --- upkeep --------------------------------------------------------------------------------
    def save_retention(self, policy: RetentionPolicy) -> None:
        """Record the policy the recorder applies, so readers can tell how far back history goes."""
        value = json.dumps(dataclasses.asdict(policy), sort_keys=True)
        with self.backend.transaction() as tx:
            tx.execute("INSERT INTO settings (name, value) VALUES ('retention', ?) "
                       "ON CONFLICT (name) DO UPDATE SET value = excluded.value", [value])

    def retention(self) -> RetentionPolicy | None:
        """The policy last saved by a recorder; None if none was."""
        rows = self.backend.query("SELECT value FROM settings WHERE name = 'retention'")
        return RetentionPolicy(**json.loads(rows[0][0])) if rows else None

    def apply_retention(self, policy: RetentionPolicy, now_ns: int, max_span_s: float = 3600.0,
                        latest_ns: int | None = None) -> RetentionResult:
        """Downsample and delete what ``policy`` no longer keeps, and what lies beyond ``latest_ns``
        (see ``storage.retention``)."""
        return apply_retention(self.backend, policy, now_ns, max_span_s, latest_ns)

    def row_counts(self) -> dict[str, int]:
        """Rows per table, for health reports and tests."""
        tables = ("occupancy", "occupancy_coarse", "events", "event_tracks", "tracks", "track_zones",
                  "track_points", "acknowledgements")
        return {t: int(self.backend.query(f"SELECT COUNT(*) FROM {t}")[0][0]) for t in tables}


def _lapsed(event: Event, renewed_ns: int) -> Event:
    """An open alert whose lease ran out, as ended at its last renewal."""
    return event.model_copy(update={"end_ns": max(event.start_ns, int(renewed_ns))})


def _pivot(rows: list[tuple[Any, ...]]) -> list[OccupancyPoint]:
    """(time_ns, step_s, zone, count) rows, ordered by time, as one point per time."""
    points: list[OccupancyPoint] = []
    current: tuple[int, int] | None = None
    total, zones = 0, dict[str, int]()
    for time_ns, step_s, zone, count in rows:
        key = (int(time_ns), int(step_s))
        if key[0] != (current[0] if current else None):
            if current is not None:
                points.append(OccupancyPoint(current[0], current[1], total, zones))
            current, total, zones = key, 0, {}
        if zone == SITE:
            total = int(count)
        else:
            zones[str(zone)] = int(count)
    if current is not None:
        points.append(OccupancyPoint(current[0], current[1], total, zones))
    return points
