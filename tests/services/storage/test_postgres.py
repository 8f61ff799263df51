"""What only PostgreSQL does: connection errors, and reconnecting after losing the server."""

from __future__ import annotations

import psycopg
import pytest

from bevflow_services.storage import Batch, HistoryDatabase, StorageError, StorageUnavailable
from tests.services.gateway.feed import T0, occupancy
from tests.services.storage.databases import PostgresServer


def test_an_unreachable_server_is_one_line_without_the_password(tmp_path) -> None:
    url = f"postgresql://bevflow:s3cr3t@/history?host={tmp_path}&port=1&connect_timeout=2"
    with pytest.raises(StorageError, match="cannot connect") as err:
        HistoryDatabase.open(url)
    assert "s3cr3t" not in str(err.value) and "***" in str(err.value) and "\n" not in str(err.value)


def _drop_connection(db: HistoryDatabase) -> None:
    (pid,), = db.backend.query("SELECT pg_backend_pid()")
    with psycopg.connect(PostgresServer.shared().url(), autocommit=True) as admin:
        admin.execute("SELECT pg_terminate_backend(%s)", [pid])  # as a server restart would


def test_a_write_on_a_lost_connection_fails_once_and_the_next_one_reconnects() -> None:
    with HistoryDatabase.open(PostgresServer.shared().new_database()) as db:
        _drop_connection(db)
        batch = Batch()
        batch.add_occupancy(occupancy(T0, 5))
        with pytest.raises(StorageUnavailable):
            db.write(batch)  # the recorder keeps the batch and tries again
        db.write(batch)
        assert [p.total for p in db.occupancy()] == [5]


def test_a_read_on_a_lost_connection_is_tried_again_at_once() -> None:
    with HistoryDatabase.open(PostgresServer.shared().new_database()) as db:
        _drop_connection(db)
        assert db.occupancy() == []


def test_the_password_comes_from_a_file_or_pgpassword_not_the_url(tmp_path, monkeypatch) -> None:
    secret = tmp_path / "db-password"
    secret.write_text("from-a-file\n")
    url = PostgresServer.shared().new_database()  # trust authentication: any password gets in
    monkeypatch.setenv("BEVFLOW_DB_PASSWORD_FILE", str(secret))
    with HistoryDatabase.open(url) as db:
        assert db.backend._connection().info.password == "from-a-file"
    monkeypatch.delenv("BEVFLOW_DB_PASSWORD_FILE")
    monkeypatch.setenv("PGPASSWORD", "from-the-environment")  # libpq's own variable
    with HistoryDatabase.open(url) as db:
        assert db.backend._connection().info.password == "from-the-environment"


@pytest.mark.parametrize(("content", "message"), [(None, "cannot read"), ("", "is empty")])
def test_a_bad_password_file_is_one_line(tmp_path, monkeypatch, content, message) -> None:
    secret = tmp_path / "db-password"
    if content is not None:
        secret.write_text(content)
    monkeypatch.setenv("BEVFLOW_DB_PASSWORD_FILE", str(secret))
    with pytest.raises(StorageError, match=f"BEVFLOW_DB_PASSWORD_FILE: .*{message}"):
        HistoryDatabase.open(f"postgresql://bevflow@/history?host={tmp_path}&port=1")


def test_a_password_in_the_url_wins_over_the_file(tmp_path, monkeypatch) -> None:
    from bevflow_services.storage.postgres import password_from_file

    monkeypatch.setenv("BEVFLOW_DB_PASSWORD_FILE", str(tmp_path / "missing"))
    assert password_from_file("postgresql://bevflow:given@db/history") == {}
