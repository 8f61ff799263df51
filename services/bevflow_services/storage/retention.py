"""Retention: per-second occupancy becomes coarse beyond the fine window, and everything is
deleted beyond its retention (``RetentionPolicy``).

Each call does a bounded amount of work, at most ``max_span_s`` of capture time per table, each
table in its own short transaction, so a recorder that calls it between two commits never holds
the database long enough to delay its next commit by much; ``RetentionResult.done`` says whether
more is left. Every step is idempotent: a call killed half-way is finished by the next one.

Cut-offs for the occupancy roll-up are aligned to the coarse step, so a coarse bucket is always
built from all the seconds of it that were stored.
"""

from __future__ import annotations

from bevflow_services.storage.backend import Backend, Transaction
from bevflow_services.storage.records import RetentionPolicy, RetentionResult
from bevflow.units import NS_PER_S

ROLL_UP = (
    "INSERT INTO occupancy_coarse (time_ns, zone, step_s, max_people, mean_people, seconds) "
    "SELECT time_ns / ? * ?, zone, ?, MAX(people), AVG(people), COUNT(*) FROM occupancy WHERE time_ns < ? "
    "GROUP BY 1, 2 "
    "ON CONFLICT (time_ns, zone) DO UPDATE SET "
    "max_people = CASE WHEN excluded.max_people > occupancy_coarse.max_people "
    "THEN excluded.max_people ELSE occupancy_coarse.max_people END, "
    "mean_people = (occupancy_coarse.mean_people * occupancy_coarse.seconds + excluded.mean_people * excluded.seconds) "
    "/ (occupancy_coarse.seconds + excluded.seconds), "
    "seconds = occupancy_coarse.seconds + excluded.seconds"
)


def _oldest(tx: Transaction, table: str, column: str) -> int | None:
    (oldest,), = tx.execute(f"SELECT MIN({column}) FROM {table}")
    return None if oldest is None else int(oldest)


def _slice_end(tx: Transaction, table: str, column: str, cutoff: int, span_ns: int, align_ns: int = 1) -> int | None:
    """Where this call stops (exclusive): ``cutoff``, or ``span_ns`` past the oldest row, cut on
    a multiple of ``align_ns`` but one step at least; None when nothing is older than ``cutoff``."""
    oldest = _oldest(tx, table, column)
    if oldest is None or oldest >= cutoff:
        return None
    upto = oldest + span_ns
    if upto >= cutoff:
        return cutoff
    return max(upto // align_ns * align_ns, oldest // align_ns * align_ns + align_ns)


def _finished(tx: Transaction, table: str, column: str, cutoff: int) -> bool:
    oldest = _oldest(tx, table, column)
    return oldest is None or oldest >= cutoff


# Rows with a capture time beyond the trusted bound (``bevflow.capture_time``): a forged message
# or a wrong clock wrote them before the bus refused such times, and left alone they would sort
# first for centuries and never age out.
FUTURE_ROWS = (
    ("DELETE FROM event_tracks WHERE event_id IN (SELECT id FROM events WHERE start_ns > ? OR end_ns > ?)", 2),
    ("DELETE FROM acknowledgements WHERE event_id IN (SELECT id FROM events WHERE start_ns > ? OR end_ns > ?)", 2),
    ("DELETE FROM events WHERE start_ns > ? OR end_ns > ?", 2),
    ("DELETE FROM track_zones WHERE track_id IN (SELECT track_id FROM tracks WHERE first_ns > ?)", 1),
    ("DELETE FROM tracks WHERE first_ns > ?", 1),
    ("DELETE FROM track_zones WHERE first_ns > ?", 1),
    ("UPDATE track_zones SET last_ns = first_ns WHERE last_ns > ?", 1),
    ("DELETE FROM track_points WHERE time_ns > ?", 1),
    ("UPDATE tracks SET last_ns = COALESCE((SELECT MAX(time_ns) FROM track_points p WHERE p.track_id = tracks.track_id), "
     "first_ns) WHERE last_ns > ?", 1),
    ("DELETE FROM occupancy WHERE time_ns > ?", 1),
    ("DELETE FROM occupancy_coarse WHERE time_ns > ?", 1),
)


def purge_future(backend: Backend, latest_ns: int) -> int:
    """Delete (or, for a last sighting, pull back) what lies beyond ``latest_ns``; returns the
    rows deleted."""
    deleted = 0
    with backend.transaction() as tx:
        for statement, uses in FUTURE_ROWS:
            rows = tx.rowcount(statement, [latest_ns] * uses)
            deleted += rows if statement.startswith("DELETE") else 0
    return deleted


def apply_retention(backend: Backend, policy: RetentionPolicy, now_ns: int, max_span_s: float = 3600.0,
                    latest_ns: int | None = None) -> RetentionResult:
    """Apply ``policy`` as of ``now_ns`` (capture-time nanoseconds), up to ``max_span_s`` per table;
    with ``latest_ns``, first delete what lies beyond it (``purge_future``)."""
    span = max(int(max_span_s * NS_PER_S), 1)
    step = policy.coarse_step_s * NS_PER_S
    deleted: dict[str, int] = {}
    done = True
    if latest_ns is not None:
        deleted["future"] = purge_future(backend, latest_ns)

    # The fine cut-off is on a coarse step's edge, so a coarse bucket gets all its seconds at once.
    fine_cutoff = (now_ns - int(policy.fine_s * NS_PER_S)) // step * step
    rolled = 0
    with backend.transaction() as tx:
        upto = _slice_end(tx, "occupancy", "time_ns", fine_cutoff, span, step)
        if upto is not None:
            tx.execute(ROLL_UP, [step, step, policy.coarse_step_s, upto])
            rolled = tx.rowcount("DELETE FROM occupancy WHERE time_ns < ?", [upto])
        done &= _finished(tx, "occupancy", "time_ns", fine_cutoff)

    def delete(table: str, column: str, cutoff: int) -> None:
        nonlocal done
        with backend.transaction() as tx:
            upto = _slice_end(tx, table, column, cutoff, span)
            deleted[table] = 0 if upto is None else tx.rowcount(f"DELETE FROM {table} WHERE {column} < ?", [upto])
            done &= _finished(tx, table, column, cutoff)

    delete("occupancy_coarse", "time_ns", now_ns - int(policy.occupancy_s * NS_PER_S))
    delete("track_points", "time_ns", now_ns - int(policy.tracks_s * NS_PER_S))

    track_cutoff = now_ns - int(policy.tracks_s * NS_PER_S)
    with backend.transaction() as tx:
        tx.execute("DELETE FROM track_zones WHERE track_id IN (SELECT track_id FROM tracks WHERE last_ns < ?)", [track_cutoff])
        deleted["tracks"] = tx.rowcount("DELETE FROM tracks WHERE last_ns < ?", [track_cutoff])

    # An alert goes once it has been over for the retention time; one never ended (its tracker
    # died mid-alert) goes by its start.
    event_cutoff = now_ns - int(policy.events_s * NS_PER_S)
    old_events = "SELECT id FROM events WHERE COALESCE(end_ns, start_ns) < ?"
    with backend.transaction() as tx:
        tx.execute(f"DELETE FROM event_tracks WHERE event_id IN ({old_events})", [event_cutoff])
        tx.execute(f"DELETE FROM acknowledgements WHERE event_id IN ({old_events})", [event_cutoff])
        deleted["events"] = tx.rowcount("DELETE FROM events WHERE COALESCE(end_ns, start_ns) < ?", [event_cutoff])
    return RetentionResult(rolled_up_rows=rolled, deleted=deleted, done=done)
