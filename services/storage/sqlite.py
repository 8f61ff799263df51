"""SQLite, the embedded default: one file, WAL journal, every commit synced to disk.

WAL lets the gateway read while the recorder writes, from another process. ``synchronous=FULL``
syncs the WAL at every commit, so a committed batch survives a killed process and a power cut;
at the recorder's commit rate (a few per second) that costs nothing noticeable. Writers wait up
to ``busy_timeout_s`` for each other's locks instead of failing at once.
"""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from bevflow_services.storage.backend import Dialect, Row
from bevflow_services.storage.records import StorageError, StorageUnavailable

DIALECT = Dialect(name="sqlite", id_pk="INTEGER PRIMARY KEY AUTOINCREMENT", key_text="TEXT", migration_lock=None)


def sqlite_path(url: str) -> str:
    """The file a SQLite URL names: ``sqlite:///abs/path``, ``sqlite:rel/path`` or a bare path."""
    for prefix in ("sqlite:///", "sqlite://", "sqlite:"):
        if url.startswith(prefix):
            rest = url[len(prefix):]
            return "/" + rest if prefix == "sqlite:///" else rest
    return url


class _Cursor:
    def __init__(self, conn: sqlite3.Connection) -> None:
        self._conn = conn

    def execute(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        return [tuple(r) for r in self._conn.execute(sql, tuple(params)).fetchall()]

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> None:
        if rows:
            self._conn.executemany(sql, [tuple(r) for r in rows])

    def rowcount(self, sql: str, params: Sequence[Any] = ()) -> int:
        return self._conn.execute(sql, tuple(params)).rowcount


def _unavailable(exc: sqlite3.Error) -> bool:
    return isinstance(exc, sqlite3.OperationalError) and any(
        word in str(exc) for word in ("locked", "busy", "disk I/O", "unable to open"))


class SqliteBackend:
    """A SQLite database file, created if missing (its folder must exist)."""

    dialect = DIALECT

    def __init__(self, url: str, *, busy_timeout_s: float = 10.0) -> None:
        self.url = url
        path = sqlite_path(url)
        if path != ":memory:" and not Path(path).parent.is_dir():
            raise StorageError(f"database {path}: folder {Path(path).parent} does not exist")
        try:
            self._conn = sqlite3.connect(path, timeout=busy_timeout_s, isolation_level=None, check_same_thread=False)
            self._conn.execute("PRAGMA journal_mode=WAL")
            self._conn.execute("PRAGMA synchronous=FULL")
            self._conn.execute(f"PRAGMA busy_timeout={int(busy_timeout_s * 1000)}")
        except sqlite3.Error as exc:
            raise StorageError(f"database {path}: cannot open it as SQLite ({exc})") from None
        self._lock = threading.RLock()

    @contextmanager
    def transaction(self) -> Iterator[_Cursor]:
        with self._lock:
            try:
                # IMMEDIATE takes the write lock up front: two writers queue at BEGIN instead of
                # one failing half-way through with SQLITE_BUSY.
                self._conn.execute("BEGIN IMMEDIATE")
            except sqlite3.Error as exc:
                raise (StorageUnavailable if _unavailable(exc) else StorageError)(f"database {self.url}: {exc}") from None
            try:
                yield _Cursor(self._conn)
                self._conn.execute("COMMIT")
            except BaseException as exc:
                if self._conn.in_transaction:
                    self._conn.execute("ROLLBACK")
                if isinstance(exc, sqlite3.Error) and _unavailable(exc):
                    raise StorageUnavailable(f"database {self.url}: {exc}") from None
                raise

    def query(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        with self._lock:
            try:
                return _Cursor(self._conn).execute(sql, params)
            except sqlite3.Error as exc:
                if _unavailable(exc):
                    raise StorageUnavailable(f"database {self.url}: {exc}") from None
                raise

    def close(self) -> None:
        with self._lock:
            self._conn.close()
