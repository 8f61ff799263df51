"""Throwaway databases for tests: a SQLite file, or a database in a PostgreSQL cluster that the
test run starts itself (initdb + pg_ctl in a temporary folder, on a unix socket only) and stops
when it ends. Tests that need PostgreSQL are skipped, with the reason, only when it cannot start.

Import ``database_url`` as a fixture: it is parametrized over both backends.
"""

from __future__ import annotations

import atexit
import glob
import itertools
import os
import pwd
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

BACKENDS = ("sqlite", "postgresql")


def _pg_bin(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    candidates = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"), key=lambda p: int(p.split("/")[4]))
    return candidates[-1] if candidates else None


class PostgresServer:
    """One cluster per test run, shared by every test module (started on first use)."""

    _shared: PostgresServer | None = None
    _failure: str | None = None
    _names = itertools.count()

    def __init__(self) -> None:
        initdb, pg_ctl = _pg_bin("initdb"), _pg_bin("pg_ctl")
        if not initdb or not pg_ctl:
            raise RuntimeError("PostgreSQL server binaries (initdb, pg_ctl) are not installed")
        self.pg_ctl = pg_ctl
        self.run_as: list[str] = []
        owner = None
        if os.geteuid() == 0:  # the server refuses to run as root
            try:
                owner = pwd.getpwnam("postgres")
            except KeyError:
                raise RuntimeError("running as root and there is no 'postgres' user to run the server as") from None
            self.run_as = ["runuser", "-u", "postgres", "--"]
        self.root = Path(tempfile.mkdtemp(prefix="bevflow-pg-"))
        if owner is not None:
            os.chown(self.root, owner.pw_uid, owner.pw_gid)
        self.data = self.root / "data"
        self.port = 5432 + os.getpid() % 20000  # only names the socket file: nothing listens on TCP
        self._run([initdb, "-D", str(self.data), "-U", "bevflow", "--auth=trust", "-E", "UTF8", "--no-sync"])
        options = f"-p {self.port} -k {self.root} -c listen_addresses='' -c fsync=off -c max_connections=100"
        self._run([pg_ctl, "-D", str(self.data), "-l", str(self.root / "server.log"), "-w", "-t", "60",
                   "-o", options, "start"])
        atexit.register(self.stop)

    def _run(self, argv: list[str]) -> None:
        done = subprocess.run([*self.run_as, *argv], capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            log = (self.root / "server.log")
            tail = log.read_text(errors="replace")[-800:] if log.exists() else ""
            raise RuntimeError(f"{Path(argv[0]).name} failed: {(done.stderr or done.stdout).strip()[-800:]} {tail}")

    def url(self, schema: str | None = None) -> str:
        url = f"postgresql://bevflow@/postgres?host={self.root}&port={self.port}"
        return url if schema is None else f"{url}&options=-csearch_path%3D{schema}"

    def new_database(self) -> str:
        """The URL of a new, empty database: a schema of its own, which is much quicker to make
        than a database, and as separate for these tables."""
        import psycopg

        name = f"test_{os.getpid()}_{next(self._names)}"
        with psycopg.connect(self.url(), autocommit=True) as conn:
            conn.execute(f"CREATE SCHEMA {name}")
        return self.url(name)

    def stop(self) -> None:
        if self.data.exists():
            subprocess.run([*self.run_as, self.pg_ctl, "-D", str(self.data), "-m", "immediate", "stop"],
                           capture_output=True, timeout=60)
        shutil.rmtree(self.root, ignore_errors=True)

    @classmethod
    def shared(cls) -> PostgresServer:
        """The run's cluster; skips the calling test (with the reason) when it cannot start."""
        if cls._shared is None and cls._failure is None:
            try:
                cls._shared = PostgresServer()
            except (RuntimeError, OSError, subprocess.SubprocessError) as exc:
                cls._failure = str(exc)
        if cls._shared is None:
            pytest.skip(f"PostgreSQL cannot start here, so its tests are skipped: {cls._failure}")
        return cls._shared


def new_database_url(kind: str, folder: Path) -> str:
    if kind == "sqlite":
        return str(folder / "history.db")
    return PostgresServer.shared().new_database()


@pytest.fixture(params=BACKENDS)
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty database of each backend in turn: a SQLite file path or a postgresql:// URL."""
    return new_database_url(request.param, tmp_path)


def damaged_sqlite_history(path: Path, rows: int = 200, *, whole: bool = False) -> Path:
    """A SQLite history with ``rows`` seconds of occupancy and positions whose data pages are
    overwritten while its table of tables is intact, so it opens and fails when used: a file
    corrupted in the middle (``whole``: every page after the first, so it fails when opened)."""
    import sqlite3

    from bevflow_services.storage import Batch, HistoryDatabase
    from tests.services.gateway.feed import S, T0, occupancy, tracks

    with HistoryDatabase.open(str(path)) as db:
        for k in range(rows):
            batch = Batch()
            batch.add_occupancy(occupancy(T0 + k * S, k % 5))
            batch.add_track_sample(tracks(T0 + k * S, {i: (float(i), 0.0) for i in range(20)}))
            db.write(batch)
        db.backend.query("PRAGMA wal_checkpoint(TRUNCATE)")
    with sqlite3.connect(path) as conn:
        size = conn.execute("PRAGMA page_size").fetchone()[0]
        pages = [n for (n,) in conn.execute(
            "SELECT pageno FROM dbstat WHERE name IN ('occupancy', 'track_points') AND pagetype = 'leaf'")]
    data = bytearray(path.read_bytes())
    garbage = bytes((k * 7919 + 13) % 256 for k in range(size))
    for n in range(2, len(data) // size + 1) if whole else pages:
        data[(n - 1) * size:n * size] = garbage
    path.write_bytes(bytes(data))
    return path
