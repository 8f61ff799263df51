from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from bevflow_services.storage import HistoryDatabase, StorageDamaged, StorageError, StorageUnavailable
from bevflow_services.storage.sqlite import SqliteBackend, sqlite_path
from tests.services.storage.databases import damaged_sqlite_history


@pytest.mark.parametrize(
    ("url", "path"),
    [
        ("sqlite:///var/lib/h.db", "/var/lib/h.db"),
        ("sqlite:h.db", "h.db"),
        ("sqlite://h.db", "h.db"),
        ("/var/lib/h.db", "/var/lib/h.db"),
        (":memory:", ":memory:"),
    ],
)
def test_sqlite_paths(url: str, path: str) -> None:
    assert sqlite_path(url) == path


def test_the_file_uses_a_wal_journal_synced_at_every_commit(tmp_path: Path) -> None:
    with HistoryDatabase.open(str(tmp_path / "h.db")) as db:
        assert db.backend.query("PRAGMA journal_mode") == [("wal",)]
        assert db.backend.query("PRAGMA synchronous") == [(2,)]  # FULL
    assert (tmp_path / "h.db").exists()


def test_a_missing_folder_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(StorageError, match=r"folder .*nowhere does not exist"):
        HistoryDatabase.open(str(tmp_path / "nowhere" / "h.db"))


def test_a_file_that_is_not_sqlite_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "h.db"
    path.write_bytes(b"this is not a database" * 100)
    with pytest.raises(StorageError, match="h.db"):
        HistoryDatabase.open(str(path))


def test_a_writer_that_cannot_get_the_lock_in_time_is_told_to_retry(tmp_path: Path) -> None:
    path = tmp_path / "h.db"
    HistoryDatabase.open(str(path)).close()
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")  # another process in the middle of a write
    backend = SqliteBackend(str(path), busy_timeout_s=0.05)
    try:
        with pytest.raises(StorageUnavailable, match="locked"):
            with backend.transaction() as tx:
                tx.execute("DELETE FROM occupancy")
        holder.execute("ROLLBACK")
        with backend.transaction() as tx:  # and it works once the lock is free
            tx.execute("DELETE FROM occupancy")
    finally:
        backend.close()
        holder.close()


@pytest.mark.parametrize(
    ("whole", "use"),
    [
        (False, lambda db: db.trajectory(5)),
        (False, lambda db: db.nearby_positions(5, 2.0)),
        (False, lambda db: db.occupancy()),
        (True, lambda db: db.row_counts()),  # refused when opened
    ],
    ids=["trajectory", "contacts", "occupancy", "at-open"],
)
def test_a_file_damaged_in_the_middle_is_one_clear_error(tmp_path: Path, whole: bool, use) -> None:
    path = damaged_sqlite_history(tmp_path / "h.db", whole=whole)
    with pytest.raises(StorageDamaged) as caught:
        with HistoryDatabase.open(str(path)) as db:
            use(db)
    message = str(caught.value)
    assert "\n" not in message and f"database {path} is damaged" in message and "restore the latest backup" in message
