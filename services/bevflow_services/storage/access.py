"""``AccessStore``: users, dashboard sessions, API tokens and the audit log, in the history database.

The same SQLite file or PostgreSQL database as the history (its ``users``, ``sessions``,
``api_tokens`` and ``audit`` tables), so one backup keeps both. Passwords arrive here already
hashed (the gateway hashes them with argon2); sessions and API tokens are kept as SHA-256 digests,
so a stolen copy of the database holds no usable credential.

>>> store = AccessStore.open("history.db")                              # doctest: +SKIP
>>> store.add_user("ana", "operator", password_hash, now_ns)             # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

from bevflow_services.storage.database import Database
from bevflow_services.storage.records import StorageError
from bevflow_services.storage.store import INT64_MAX, INT64_MIN, int64

ROLES = ("viewer", "operator", "admin")  # each can do what the ones before it can
NAME_MAX = 64


def digest(secret: str) -> str:
    """What is stored for a session or API token: its SHA-256, hex. The secrets are random and
    long, so a fast hash is enough (passwords are the ones needing argon2)."""
    return hashlib.sha256(secret.encode()).hexdigest()


@dataclass(frozen=True)
class User:
    name: str
    role: str
    password_hash: str
    created_ns: int


@dataclass(frozen=True)
class ApiToken:
    id: int
    user: str
    label: str
    created_ns: int


@dataclass(frozen=True)
class AuditEntry:
    """One access to personal data: ``user`` did ``action`` (on ``track_id``) from ``client``."""

    id: int
    time_ns: int
    user: str
    action: str
    track_id: int | None
    client: str
    detail: str


def _storable(text: str) -> str:
    """``text`` as both databases store it: PostgreSQL refuses NUL characters in text."""
    return text.replace("\x00", "\\x00")


def check_user_name(name: str) -> str:
    """``name`` if it is a usable user name; ``ValueError`` saying why not."""
    if not name or len(name) > NAME_MAX or name != name.strip() or not name.isprintable() or ":" in name:
        raise ValueError(f"user name {name!r}: 1 to {NAME_MAX} printable characters, no ':' and no surrounding spaces")
    return name


def check_role(role: str) -> str:
    if role not in ROLES:
        raise ValueError(f"role {role!r}: must be one of {', '.join(ROLES)}")
    return role


class AccessStore(Database):
    """Users, sessions, tokens and audit rows behind a ``Backend``; safe to share between threads."""

    # --- users ---------------------------------------------------------------------------------
    def add_user(self, name: str, role: str, password_hash: str, now_ns: int) -> User:
        """A new user; ``ValueError`` for a bad name or role, or a name already taken."""
        check_user_name(name)
        check_role(role)
        with self.backend.transaction() as tx:
            if tx.execute("SELECT 1 FROM users WHERE name = ?", [name]):
                raise ValueError(f"user {name!r} already exists")
            tx.execute("INSERT INTO users (name, role, password_hash, created_ns) VALUES (?, ?, ?, ?)",
                       [name, role, password_hash, int(now_ns)])
        return User(name, role, password_hash, int(now_ns))

    def add_first_admin(self, name: str, password_hash: str, now_ns: int) -> User | None:
        """Create admin ``name`` only if there are no users yet (first-run setup); None otherwise.
        One transaction, so two setups racing cannot both succeed."""
        check_user_name(name)
        with self.backend.transaction() as tx:
            if backend_lock := self.backend.dialect.migration_lock:
                tx.execute(backend_lock)  # serialise with another gateway doing the same
            if tx.execute("SELECT 1 FROM users LIMIT 1"):
                return None
            tx.execute("INSERT INTO users (name, role, password_hash, created_ns) VALUES (?, 'admin', ?, ?)",
                       [name, password_hash, int(now_ns)])
        return User(name, "admin", password_hash, int(now_ns))

    def user(self, name: str) -> User | None:
        if "\x00" in name:  # no stored name has one (see check_user_name)
            return None
        rows = self.backend.query("SELECT name, role, password_hash, created_ns FROM users WHERE name = ?", [name])
        return _user(rows[0]) if rows else None

    def users(self) -> list[User]:
        rows = self.backend.query("SELECT name, role, password_hash, created_ns FROM users ORDER BY name")
        return [_user(r) for r in rows]

    def user_count(self) -> int:
        return int(self.backend.query("SELECT COUNT(*) FROM users")[0][0])

    def set_password(self, name: str, password_hash: str) -> None:
        """Replace ``name``'s password hash and end their sessions and API tokens (a changed password
        is often a suspected leak, and a token made by whoever knew the old one must not outlive
        it); ``KeyError`` if no such user."""
        if self.user(name) is None:
            raise KeyError(f"no user {name!r}")
        with self.backend.transaction() as tx:
            if not tx.rowcount("UPDATE users SET password_hash = ? WHERE name = ?", [password_hash, name]):
                raise KeyError(f"no user {name!r}")
            tx.execute("DELETE FROM sessions WHERE user_name = ?", [name])
            tx.execute("DELETE FROM api_tokens WHERE user_name = ?", [name])

    def set_role(self, name: str, role: str) -> None:
        check_role(role)
        if self.user(name) is None:
            raise KeyError(f"no user {name!r}")
        with self.backend.transaction() as tx:
            if not tx.rowcount("UPDATE users SET role = ? WHERE name = ?", [role, name]):
                raise KeyError(f"no user {name!r}")

    def remove_user(self, name: str) -> None:
        """Delete ``name`` with their sessions and tokens; ``KeyError`` if no such user."""
        if self.user(name) is None:
            raise KeyError(f"no user {name!r}")
        with self.backend.transaction() as tx:
            if not tx.rowcount("DELETE FROM users WHERE name = ?", [name]):
                raise KeyError(f"no user {name!r}")
            tx.execute("DELETE FROM sessions WHERE user_name = ?", [name])
            tx.execute("DELETE FROM api_tokens WHERE user_name = ?", [name])

    # --- sessions ------------------------------------------------------------------------------
    def add_session(self, secret: str, user: str, now_ns: int, expires_ns: int) -> None:
        with self.backend.transaction() as tx:
            # Expired sessions are swept here, at login, rather than by a timer.
            tx.execute("DELETE FROM sessions WHERE expires_ns <= ?", [int(now_ns)])
            tx.execute("INSERT INTO sessions (digest, user_name, created_ns, expires_ns) VALUES (?, ?, ?, ?)",
                       [digest(secret), user, int(now_ns), int(expires_ns)])

    def session_user(self, secret: str, now_ns: int) -> User | None:
        """The user a session cookie belongs to, if it exists and has not expired."""
        rows = self.backend.query(
            "SELECT u.name, u.role, u.password_hash, u.created_ns FROM sessions s JOIN users u ON u.name = s.user_name "
            "WHERE s.digest = ? AND s.expires_ns > ?", [digest(secret), int(now_ns)])
        return _user(rows[0]) if rows else None

    def remove_session(self, secret: str) -> None:
        with self.backend.transaction() as tx:
            tx.execute("DELETE FROM sessions WHERE digest = ?", [digest(secret)])

    # --- API tokens ----------------------------------------------------------------------------
    def add_token(self, secret: str, user: str, label: str, now_ns: int) -> ApiToken:
        """Store a new API token of ``user``; ``KeyError`` if no such user."""
        if self.user(user) is None:
            raise KeyError(f"no user {user!r}")
        label = _storable(label)
        with self.backend.transaction() as tx:
            if not tx.execute("SELECT 1 FROM users WHERE name = ?", [user]):
                raise KeyError(f"no user {user!r}")
            (token_id,), = tx.execute(
                "INSERT INTO api_tokens (digest, user_name, label, created_ns) VALUES (?, ?, ?, ?) RETURNING id",
                [digest(secret), user, label, int(now_ns)])
        return ApiToken(int(token_id), user, label, int(now_ns))

    def token_user(self, secret: str) -> User | None:
        rows = self.backend.query(
            "SELECT u.name, u.role, u.password_hash, u.created_ns FROM api_tokens t JOIN users u ON u.name = t.user_name "
            "WHERE t.digest = ?", [digest(secret)])
        return _user(rows[0]) if rows else None

    def tokens(self, user: str | None = None) -> list[ApiToken]:
        where, params = (" WHERE user_name = ?", [_storable(user)]) if user is not None else ("", [])
        rows = self.backend.query(f"SELECT id, user_name, label, created_ns FROM api_tokens{where} ORDER BY id", params)
        return [ApiToken(int(i), str(u), str(label), int(t)) for i, u, label, t in rows]

    def revoke_token(self, token_id: int) -> None:
        with self.backend.transaction() as tx:
            if not tx.rowcount("DELETE FROM api_tokens WHERE id = ?", [int(token_id)]):
                raise KeyError(f"no API token {token_id}")

    # --- audit ---------------------------------------------------------------------------------
    def audit(self, time_ns: int, user: str, action: str, track_id: int | None, client: str, detail: str = "") -> None:
        """Record one access; a track id beyond what the database stores goes into ``detail``."""
        if track_id is not None and not INT64_MIN <= track_id <= INT64_MAX:
            track_id, detail = None, f"track_id={track_id} {detail}".strip()
        user, client, detail = _storable(user), _storable(client), _storable(detail)
        with self.backend.transaction() as tx:
            tx.execute("INSERT INTO audit (time_ns, user_name, action, track_id, client, detail) VALUES (?, ?, ?, ?, ?, ?)",
                       [int(time_ns), user, action, track_id, client, detail])

    def audit_log(self, since_ns: int | None = None, until_ns: int | None = None, user: str | None = None,
                  track_id: int | None = None, limit: int = 100, offset: int = 0) -> tuple[list[AuditEntry], int]:
        """Audit rows newest first: one page, and how many match in all."""
        where: list[str] = []
        params: list[Any] = []
        for condition, value in (("time_ns >= ?", since_ns), ("time_ns <= ?", until_ns), ("user_name = ?", user),
                                 ("track_id = ?", track_id)):
            if value is not None:
                where.append(condition)
                params.append(int64(value) if isinstance(value, int) else _storable(value))
        clause = " WHERE " + " AND ".join(where) if where else ""
        (total,), = self.backend.query(f"SELECT COUNT(*) FROM audit{clause}", params)
        rows = self.backend.query(
            f"SELECT id, time_ns, user_name, action, track_id, client, detail FROM audit{clause} "
            "ORDER BY time_ns DESC, id DESC LIMIT ? OFFSET ?", [*params, int64(limit), int64(offset)])
        entries = [AuditEntry(int(i), int(t), str(u), str(a), None if k is None else int(k), str(c), str(d))
                   for i, t, u, a, k, c, d in rows]
        return entries, int(total)


def _user(row: tuple[Any, ...]) -> User:
    name, role, password_hash, created_ns = row
    return User(str(name), str(role), str(password_hash), int(created_ns))


__all__ = ["ROLES", "AccessStore", "ApiToken", "AuditEntry", "StorageError", "User", "check_role",
           "check_user_name", "digest"]
