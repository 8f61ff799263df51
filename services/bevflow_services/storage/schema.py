"""The history tables, and the migrations that create and update them.

``schema_version`` records every migration applied. ``migrate`` applies the missing ones in
order, each in its own transaction, and refuses a database written by a newer release (whose
tables this code may misread). To change the schema, append a migration; never edit one that has
shipped.

Tables (times are capture times in ns; ``zone`` '' is the whole site):

- ``occupancy``: per second and zone, the highest count in that second (the fine series).
- ``occupancy_coarse``: per ``step_s`` bucket and zone, the highest and mean per-second count,
  for data older than the fine retention window.
- ``events``: one row per alert id, its JSON body updated in place when the end arrives;
  ``event_tracks`` indexes them by track.
- ``tracks``, ``track_zones``, ``track_points``: per track when it was seen, which zones it was
  in and when, and its feet positions (no images, ever).
- ``acknowledgements``: who acknowledged an alert, and when.
- ``settings``: what the recorder was told (its retention policy, as JSON), for readers.
- ``users``, ``sessions``, ``api_tokens``, ``audit``: access control (``storage.access``).
"""

from __future__ import annotations

import time

from bevflow_services.storage.backend import Backend, Dialect
from bevflow_services.storage.records import StorageError

V1 = [
    """CREATE TABLE occupancy (
        time_ns BIGINT NOT NULL,
        zone {key_text} NOT NULL,
        people INTEGER NOT NULL,
        PRIMARY KEY (time_ns, zone))""",
    """CREATE TABLE occupancy_coarse (
        time_ns BIGINT NOT NULL,
        zone {key_text} NOT NULL,
        step_s INTEGER NOT NULL,
        max_people INTEGER NOT NULL,
        mean_people DOUBLE PRECISION NOT NULL,
        seconds INTEGER NOT NULL,
        PRIMARY KEY (time_ns, zone))""",
    """CREATE TABLE events (
        id {key_text} PRIMARY KEY,
        type TEXT NOT NULL,
        zone {key_text},
        start_ns BIGINT NOT NULL,
        end_ns BIGINT,
        body TEXT NOT NULL,
        recorded_ns BIGINT NOT NULL)""",
    "CREATE INDEX events_by_start ON events (start_ns)",
    """CREATE TABLE event_tracks (
        track_id BIGINT NOT NULL,
        event_id {key_text} NOT NULL,
        PRIMARY KEY (track_id, event_id))""",
    """CREATE TABLE tracks (
        track_id BIGINT PRIMARY KEY,
        first_ns BIGINT NOT NULL,
        last_ns BIGINT NOT NULL)""",
    "CREATE INDEX tracks_by_last ON tracks (last_ns)",
    """CREATE TABLE track_zones (
        track_id BIGINT NOT NULL,
        zone {key_text} NOT NULL,
        first_ns BIGINT NOT NULL,
        last_ns BIGINT NOT NULL,
        PRIMARY KEY (track_id, zone))""",
    """CREATE TABLE track_points (
        track_id BIGINT NOT NULL,
        time_ns BIGINT NOT NULL,
        x DOUBLE PRECISION NOT NULL,
        y DOUBLE PRECISION NOT NULL,
        PRIMARY KEY (track_id, time_ns))""",
    "CREATE INDEX track_points_by_time ON track_points (time_ns)",
    """CREATE TABLE acknowledgements (
        id {id_pk},
        event_id {key_text} NOT NULL,
        user_name TEXT NOT NULL,
        time_ns BIGINT NOT NULL,
        note TEXT NOT NULL)""",
    "CREATE INDEX acknowledgements_by_event ON acknowledgements (event_id, time_ns)",
    "CREATE TABLE settings (name {key_text} PRIMARY KEY, value TEXT NOT NULL)",
]

# Access control (``bevflow_services.storage.access``): users, dashboard sessions, API tokens,
# and the audit log of who traced which person. Sessions and tokens are stored as SHA-256 digests.
V2 = [
    """CREATE TABLE users (
        name {key_text} PRIMARY KEY,
        role TEXT NOT NULL,
        password_hash TEXT NOT NULL,
        created_ns BIGINT NOT NULL)""",
    """CREATE TABLE sessions (
        digest {key_text} PRIMARY KEY,
        user_name {key_text} NOT NULL,
        created_ns BIGINT NOT NULL,
        expires_ns BIGINT NOT NULL)""",
    "CREATE INDEX sessions_by_user ON sessions (user_name)",
    """CREATE TABLE api_tokens (
        id {id_pk},
        digest {key_text} NOT NULL UNIQUE,
        user_name {key_text} NOT NULL,
        label TEXT NOT NULL,
        created_ns BIGINT NOT NULL)""",
    "CREATE INDEX api_tokens_by_user ON api_tokens (user_name)",
    """CREATE TABLE audit (
        id {id_pk},
        time_ns BIGINT NOT NULL,
        user_name TEXT NOT NULL,
        action TEXT NOT NULL,
        track_id BIGINT,
        client TEXT NOT NULL,
        detail TEXT NOT NULL)""",
    "CREATE INDEX audit_by_time ON audit (time_ns)",
]

# Open alerts by when they were last written or renewed: what the recorder ends when their lease
# runs out (``bevflow.alert_lease``), found without reading every alert ever stored.
V3 = ["CREATE INDEX events_open_by_renewal ON events (recorded_ns) WHERE end_ns IS NULL"]

MIGRATIONS: list[list[str]] = [V1, V2, V3]
LATEST = len(MIGRATIONS)


def _render(statement: str, dialect: Dialect) -> str:
    return statement.format(key_text=dialect.key_text, id_pk=dialect.id_pk)


def schema_version(backend: Backend) -> int:
    """The newest migration applied; 0 for an empty database."""
    tables = _tables(backend)
    if "schema_version" not in tables:
        if tables & {"occupancy", "events"}:
            raise StorageError(f"database {backend.url} has tables but no schema_version: it is not a bevflow history")
        return 0
    (version,), = backend.query("SELECT COALESCE(MAX(version), 0) FROM schema_version")
    return int(version)


def _tables(backend: Backend) -> set[str]:
    if backend.dialect.name == "sqlite":
        rows = backend.query("SELECT name FROM sqlite_master WHERE type = 'table'")
    else:
        rows = backend.query("SELECT table_name FROM information_schema.tables WHERE table_schema = current_schema()")
    return {str(r[0]) for r in rows}


def migrate(backend: Backend) -> int:
    """Bring the database to ``LATEST``; returns the version it had before."""
    before = schema_version(backend)
    if before > LATEST:
        raise StorageError(f"database {backend.url} has schema version {before}, newer than this release "
                           f"understands ({LATEST}): upgrade bevflow")
    for version in range(before + 1, LATEST + 1):
        with backend.transaction() as tx:
            if backend.dialect.migration_lock:
                tx.execute(backend.dialect.migration_lock)
            tx.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER PRIMARY KEY, applied_ns BIGINT NOT NULL)")
            (done,), = tx.execute("SELECT COALESCE(MAX(version), 0) FROM schema_version")
            if done >= version:  # another process got here first
                continue
            for statement in MIGRATIONS[version - 1]:
                tx.execute(_render(statement, backend.dialect))
            tx.execute("INSERT INTO schema_version (version, applied_ns) VALUES (?, ?)", (version, time.time_ns()))
    return before
