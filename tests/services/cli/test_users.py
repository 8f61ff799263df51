"""``bevflow users``: add, list, password, token, revoke, remove, on a SQLite database."""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import pytest
from argon2 import PasswordHasher

from bevflow_services.cli import users
from bevflow_services.runtime import UserError
from bevflow_services.storage.access import AccessStore


def run(argv: list[str], stdin: str = "", monkeypatch: pytest.MonkeyPatch | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bevflow")
    users.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["users", *argv])
    if monkeypatch is not None:
        monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    return args.func(args)


def test_a_user_is_added_with_a_hashed_password_listed_and_removed(tmp_path: Path, monkeypatch, capsys) -> None:
    db = str(tmp_path / "history.db")
    assert run(["--db", db, "add", "ana", "--role", "admin", "--password-stdin"], "a long password\n", monkeypatch) == 0
    with AccessStore.open(db) as store:
        stored = store.user("ana")
    assert stored.role == "admin" and stored.password_hash.startswith("$argon2id$")
    assert "a long password" not in stored.password_hash
    assert PasswordHasher().verify(stored.password_hash, "a long password")
    run(["--db", db, "list"])
    assert "ana" in capsys.readouterr().out
    run(["--db", db, "remove", "ana"])
    run(["--db", db, "list"])
    assert "no users yet" in capsys.readouterr().out


def test_a_token_is_printed_once_and_can_be_revoked(tmp_path: Path, monkeypatch, capsys) -> None:
    db = str(tmp_path / "history.db")
    run(["--db", db, "add", "screen", "--role", "viewer", "--password-stdin"], "a long password\n", monkeypatch)
    capsys.readouterr()
    run(["--db", db, "token", "screen", "--label", "lobby"])
    token = capsys.readouterr().out.strip()
    with AccessStore.open(db) as store:
        assert store.token_user(token).name == "screen"
        (listed,) = store.tokens()
    run(["--db", db, "list"])
    assert f"#{listed.id} lobby" in capsys.readouterr().out
    run(["--db", db, "revoke", str(listed.id)])
    with AccessStore.open(db) as store:
        assert store.token_user(token) is None


def test_a_new_password_replaces_the_old(tmp_path: Path, monkeypatch) -> None:
    db = str(tmp_path / "history.db")
    run(["--db", db, "add", "ana", "--role", "operator", "--password-stdin"], "first password\n", monkeypatch)
    run(["--db", db, "password", "ana", "--password-stdin"], "second password\n", monkeypatch)
    with AccessStore.open(db) as store:
        assert PasswordHasher().verify(store.user("ana").password_hash, "second password")


@pytest.mark.parametrize(
    ("argv", "stdin", "message"),
    [
        (["add", "ana", "--role", "admin", "--password-stdin"], "short\n", "at least 10 characters"),
        (["add", "ana", "--role", "admin"], "", "no terminal to type a password at"),
        (["add", "bo b ", "--role", "admin", "--password-stdin"], "a long password\n", "user name"),
        (["remove", "nobody"], "", "no user 'nobody'"),
        (["token", "nobody"], "", "no user 'nobody'"),
        (["revoke", "99"], "", "no API token 99"),
    ],
)
def test_mistakes_are_one_clear_line(tmp_path: Path, monkeypatch, argv: list[str], stdin: str, message: str) -> None:
    with pytest.raises(UserError, match=message):
        run(["--db", str(tmp_path / "history.db"), *argv], stdin, monkeypatch)


def test_a_database_that_cannot_open_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="--db: database"):
        run(["--db", str(tmp_path / "no" / "such" / "folder.db"), "list"])
