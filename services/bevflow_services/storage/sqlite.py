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
from bevflow_services.storage.records import StorageDamaged, StorageError, StorageUnavailable

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


def _damaged(exc: sqlite3.Error) -> bool:
    # SQLITE_CORRUPT and SQLITE_NOTADB: pages overwritten or the file is something else.
    return isinstance(exc, sqlite3.DatabaseError) and any(
        words in str(exc) for words in ("malformed", "not a database", "corrupt"))


def _is_sqlite(path: Path) -> bool:
    """Whether a file starts as SQLite files do: a damaged database, not some other file."""
    with path.open("rb") as file:
        return file.read(16) == b"SQLite format 3\x00"


def _one_line(url: str, exc: sqlite3.Error) -> StorageError:
    """What a failed call tells the user: damaged, unavailable for now, or another error."""
    if _damaged(exc):
        path = sqlite_path(url)
        return StorageDamaged(f"database {path} is damaged ({exc}): move it aside and restore the latest backup "
                              f"(sqlite3 {path} .recover may save what it still holds)")
    return (StorageUnavailable if _unavailable(exc) else StorageError)(f"database {url}: {exc}")


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
            if _damaged(exc) and Path(path).is_file() and _is_sqlite(Path(path)):
                raise _one_line(url, exc) from None
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
                raise _one_line(self.url, exc) from None
            try:
                yield _Cursor(self._conn)
                self._conn.execute("COMMIT")
            except BaseException as exc:
                self._roll_back()
                if isinstance(exc, sqlite3.Error) and (_unavailable(exc) or _damaged(exc)):
                    raise _one_line(self.url, exc) from None
                raise

    def _roll_back(self) -> None:
        if self._conn.in_transaction:
            try:
                self._conn.execute("ROLLBACK")
            except sqlite3.Error:  # a damaged file may refuse even that; the error that led here says why
                pass

    def query(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        with self._lock:
            try:
                return _Cursor(self._conn).execute(sql, params)
            except sqlite3.Error as exc:
                if _unavailable(exc) or _damaged(exc):
                    raise _one_line(self.url, exc) from None
                raise

    def close(self) -> None:
        with self._lock:
            self._conn.close()
