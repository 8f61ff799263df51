"""Schema creation and migration, on both backends."""

from __future__ import annotations

import pytest

from bevflow_services.storage import HistoryDatabase, StorageError
from bevflow_services.storage.backend import open_backend
from bevflow_services.storage.schema import LATEST, migrate, schema_version
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

TABLES = {"occupancy", "occupancy_coarse", "events", "event_tracks", "tracks", "track_zones", "track_points",
          "acknowledgements"}  # and settings


def test_opening_an_empty_database_creates_every_table_once(database_url: str) -> None:  # noqa: F811
    with HistoryDatabase.open(database_url) as db:
        assert set(db.row_counts()) == TABLES and not any(db.row_counts().values())
        assert schema_version(db.backend) == LATEST
    backend = open_backend(database_url)
    try:
        assert migrate(backend) == LATEST  # already there: nothing to do
        assert backend.query("SELECT COUNT(*) FROM schema_version") == [(LATEST,)]
    finally:
        backend.close()


def test_a_database_from_a_newer_release_is_refused(database_url: str) -> None:  # noqa: F811
    HistoryDatabase.open(database_url).close()
    backend = open_backend(database_url)
    with backend.transaction() as tx:
        tx.execute("INSERT INTO schema_version (version, applied_ns) VALUES (?, ?)", [LATEST + 1, 0])
    backend.close()
    with pytest.raises(StorageError, match=f"schema version {LATEST + 1}, newer than this release"):
        HistoryDatabase.open(database_url)


def test_a_database_with_other_tables_named_like_ours_is_refused(database_url: str) -> None:  # noqa: F811
    backend = open_backend(database_url)
    with backend.transaction() as tx:
        tx.execute("CREATE TABLE events (x INTEGER)")
    backend.close()
    with pytest.raises(StorageError, match="not a bevflow history"):
        HistoryDatabase.open(database_url)
