"""PostgreSQL, for larger sites or a database shared with other tools (``postgresql://`` URLs).

One connection, shared by the threads of a process (calls are serialised). A write on a lost
connection (the server restarted) raises ``StorageUnavailable``, and the next call connects again,
so the recorder keeps its unwritten batch and retries; a read is simply tried again at once.

The password need not be in the URL (where ``ps`` and shell history would show it): without one,
it comes from the file ``BEVFLOW_DB_PASSWORD_FILE`` names (a Docker or systemd secret), else
from libpq's own ``PGPASSWORD`` or ``~/.pgpass`` (``PGPASSFILE``).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

import psycopg
from psycopg.conninfo import conninfo_to_dict

from bevflow_services.redact import redact
from bevflow_services.storage.backend import Dialect, Row
from bevflow_services.storage.records import StorageError, StorageUnavailable

DIALECT = Dialect(
    name="postgresql",
    id_pk="BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
    key_text='TEXT COLLATE "C"',
    # Two processes starting together (recorder and gateway) must not both create the tables.
    migration_lock="SELECT pg_advisory_xact_lock(7201507)",
)


PASSWORD_FILE_VARIABLE = "BEVFLOW_DB_PASSWORD_FILE"


def password_from_file(url: str, environ: Mapping[str, str] = os.environ) -> dict[str, Any]:
    """``{"password": ...}`` read from the file ``BEVFLOW_DB_PASSWORD_FILE`` names, when it is
    set and ``url`` has no password of its own; ``{}`` otherwise (libpq's defaults then apply)."""
    path = environ.get(PASSWORD_FILE_VARIABLE)
    if not path or conninfo_to_dict(url).get("password"):
        return {}
    try:
        password = open(path, encoding="utf-8").read().rstrip("\r\n")
    except OSError as exc:
        raise StorageError(f"{PASSWORD_FILE_VARIABLE}: cannot read {path} ({exc.strerror or exc})") from None
    if not password:
        raise StorageError(f"{PASSWORD_FILE_VARIABLE}: {path} is empty")
    return {"password": password}


def _sql(statement: str) -> str:
    """Placeholders in psycopg's style; the shared SQL never contains a literal ``?`` or ``%``."""
    return statement.replace("?", "%s")


class _Cursor:
    def __init__(self, cursor: psycopg.Cursor[Any]) -> None:
        self._cursor = cursor

    def execute(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        self._cursor.execute(_sql(sql), tuple(params))
        return [tuple(r) for r in self._cursor.fetchall()] if self._cursor.description else []

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> None:
        if rows:
            self._cursor.executemany(_sql(sql), [tuple(r) for r in rows])

    def rowcount(self, sql: str, params: Sequence[Any] = ()) -> int:
        self._cursor.execute(_sql(sql), tuple(params))
        return self._cursor.rowcount


class PostgresBackend:
    dialect = DIALECT

    def __init__(self, url: str, *, connect_timeout_s: int = 10) -> None:
        self.url = redact(url)
        self._dsn = url
        self._password = password_from_file(url)
        self._connect_timeout_s = connect_timeout_s
        self._lock = threading.RLock()
        self._conn: psycopg.Connection[Any] | None = None
        try:
            self._connection()
        except StorageUnavailable as exc:
            raise StorageError(str(exc)) from None

    def _connection(self) -> psycopg.Connection[Any]:
        if self._conn is not None and not self._conn.closed and not self._conn.broken:
            return self._conn
        try:
            self._conn = psycopg.connect(self._dsn, autocommit=True, connect_timeout=self._connect_timeout_s,
                                         **self._password)
        except psycopg.Error as exc:
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise StorageUnavailable(f"database {self.url}: cannot connect: {reason}") from None
        return self._conn

    @contextmanager
    def transaction(self) -> Iterator[_Cursor]:
        with self._lock:
            conn = self._connection()
            try:
                with conn.transaction(), conn.cursor() as cursor:
                    yield _Cursor(cursor)
            except psycopg.OperationalError as exc:
                raise StorageUnavailable(f"database {self.url}: {str(exc).strip()}") from None

    def query(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        """Run a read; one that fails on a connection found broken is tried once more on a new
        one (reads are safe to repeat, and the server may simply have restarted since the last)."""
        with self._lock:
            for attempt in (1, 2):
                conn = self._connection()
                try:
                    with conn.cursor() as cursor:
                        return _Cursor(cursor).execute(sql, params)
                except psycopg.OperationalError as exc:
                    if attempt == 2 or not conn.broken:
                        raise StorageUnavailable(f"database {self.url}: {str(exc).strip()}") from None
            raise AssertionError("unreachable")

    def close(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()
