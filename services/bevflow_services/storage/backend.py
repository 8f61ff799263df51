"""One interface over SQLite and PostgreSQL: run SQL, in transactions, and say which is which.

SQL is written once, with ``?`` placeholders and the subset both databases share (``ON CONFLICT
... DO UPDATE``, ``CASE`` instead of ``greatest``, ``GROUP BY 1``). What differs (column types
for an auto-increment key, binary text ordering, locking during a migration) is in ``Dialect``.

>>> backend_kind("postgresql://bevflow@db/history")
'postgresql'
>>> backend_kind("/var/lib/bevflow/history.db")
'sqlite'
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from bevflow_services.redact import redact
from bevflow_services.storage.records import StorageError

Row = tuple[Any, ...]
Kind = Literal["sqlite", "postgresql"]


@dataclass(frozen=True)
class Dialect:
    """The few pieces of SQL that differ between the backends."""

    name: Kind
    id_pk: str  # an auto-incremented integer primary key
    key_text: str  # text compared and sorted byte by byte, whatever the server's locale
    migration_lock: str | None  # SQL run first in a migration, to serialise concurrent ones


class Transaction(Protocol):
    def execute(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        """Run one statement; its rows (empty for statements that return none)."""
        ...

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> None: ...

    def rowcount(self, sql: str, params: Sequence[Any] = ()) -> int:
        """Run one statement; how many rows it changed."""
        ...


class Backend(Protocol):
    """A connection to one database, safe to share between threads (calls are serialised)."""

    dialect: Dialect
    url: str  # for messages: any password is hidden

    def transaction(self) -> AbstractContextManager[Transaction]:
        """A write transaction: committed when the block ends, rolled back if it raises. Driver
        errors that mean "not now" (locked, connection lost) raise ``StorageUnavailable``."""
        ...

    def query(self, sql: str, params: Sequence[Any] = ()) -> list[Row]:
        """Run one read-only statement outside any open transaction."""
        ...

    def close(self) -> None: ...


def backend_kind(url: str) -> Kind:
    """Which backend a URL names: ``postgresql://`` (or ``postgres://``), else a SQLite file
    (a path, or ``sqlite:///path``)."""
    if re.match(r"^postgres(ql)?://", url):
        return "postgresql"
    if re.match(r"^[a-z][a-z0-9+.-]*://", url) and not url.startswith("sqlite:"):
        raise StorageError(f"database URL {redact(url)!r}: use a SQLite file path, sqlite:///PATH or postgresql://...")
    return "sqlite"


def open_backend(url: str) -> Backend:
    """Connect to the database ``url`` names (see ``backend_kind``)."""
    if not url.strip():
        raise StorageError("database URL is empty: give a SQLite file path or a postgresql:// URL")
    if backend_kind(url) == "postgresql":
        from bevflow_services.storage.postgres import PostgresBackend

        return PostgresBackend(url)
    from bevflow_services.storage.sqlite import SqliteBackend

    return SqliteBackend(url)

