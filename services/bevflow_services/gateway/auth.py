"""Who is asking: users, roles, sessions and API tokens, and the ``require_role`` dependency.

Three roles, each able to do what the ones before it can:

- ``viewer``: the dashboard and the read-only REST API (occupancy, alerts, the live map);
- ``operator``: also acknowledges alerts and traces people (a track's path, its contacts);
- ``admin``: also the site file, calibration, users and the audit log.

A request proves who it is with a session cookie (the dashboard, after ``/login.html``) or an API
token (``Authorization: Bearer TOKEN``; websockets may pass ``?token=TOKEN`` instead, since
browsers cannot set headers on them). ``Access`` holds the store and the settings; ``create_app``
puts it at ``app.state.access``. With access control off (``Access.disabled``, loopback only)
every request acts as the admin ``local``.

>>> app.include_router(calibration.router, dependencies=[Depends(require_role("admin"))])  # doctest: +SKIP
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
import secrets
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Annotated

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError
from fastapi import Depends, HTTPException
from starlette.requests import HTTPConnection

from bevflow_services.gateway.auth_limits import LoginLimiter
from bevflow_services.gateway.password_policy import check_password
from bevflow_services.storage.access import ROLES, AccessStore, User
from bevflow.units import NS_PER_S

log = logging.getLogger(__name__)

SESSION_COOKIE = "bevflow_session"
TOKEN_PREFIX = "bvf_"
LOCAL_USER = "local"  # who every request is when access control is off
# How long the first-run setup link works: it is written to the log, which others may read later.
SETUP_LINK_S = 3600.0
# Passwords hashed or checked at once. Each argon2 call takes 64 MiB and several cores for a
# fraction of a second; beyond this many a login is refused at once (503) rather than queued, so a
# flood of logins cannot take every worker thread, the CPU and gigabytes of memory from the people
# using the site. One: on two cores, two at once let a viewer's request wait a second under a flood.
HASHING_SLOTS = 1


def role_rank(role: str) -> int:
    return ROLES.index(role)


@dataclass(frozen=True)
class Principal:
    """The user behind a request and how they proved it (``session``, ``token`` or ``off``)."""

    name: str
    role: str
    via: str

    def can(self, role: str) -> bool:
        return role_rank(self.role) >= role_rank(role)


class HashingBusy(RuntimeError):
    """Every password-hashing slot is taken; the client should try again in a second."""


def new_api_token() -> str:
    """A fresh API token, shown once: ``bvf_`` and 43 random URL-safe characters (256 bits)."""
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def is_loopback(host: str) -> bool:
    """Whether serving on ``host`` reaches this machine only (``127.0.0.1``, ``::1``, ``localhost``)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_auth_mode(auth: str, host: str) -> None:
    """``ValueError`` (with the reason) for access control off on an address others can reach."""
    if auth not in ("on", "off"):
        raise ValueError(f"--auth must be on or off, got {auth!r}")
    if auth == "off" and not is_loopback(host):
        raise ValueError(f"--auth off is only allowed when serving on loopback (--host 127.0.0.1 or ::1): on "
                         f"--host {host} anyone who can reach the port would be an administrator")


@dataclass
class Access:
    """Access control for one gateway.

    Args:
        store: where users, sessions, tokens and the audit log live.
        enabled: False: no login; every request is the admin ``local`` (loopback only).
        secure_cookies: mark the session cookie ``Secure`` (served over TLS).
        session_s: how long a dashboard login lasts.
        cors_origins: origins (``https://host:port``) whose pages may call the API; none by default.
        hasher: argon2 parameters (tests pass cheap ones).
        limiter: failed logins per name and address; ``address_limiter``: per address, any name.
    """

    store: AccessStore
    enabled: bool = True
    secure_cookies: bool = False
    session_s: float = 12 * 3600.0
    cors_origins: tuple[str, ...] = ()
    hasher: PasswordHasher = field(default_factory=PasswordHasher)
    limiter: LoginLimiter = field(default_factory=LoginLimiter)
    # Failures from one address whatever the name, against guessing across many accounts.
    address_limiter: LoginLimiter = field(default_factory=lambda: LoginLimiter(max_failures=30))
    clock: Callable[[], int] = time.time_ns
    setup_token: str | None = None  # while there are no users: the one-time first-admin token
    setup_expires_ns: int = 0
    # Access control off: answer only requests whose Host names this machine (see cross_site).
    loopback_only: bool = False
    hashing_slots: threading.BoundedSemaphore = field(default_factory=lambda: threading.BoundedSemaphore(HASHING_SLOTS))

    @classmethod
    def disabled(cls, store: AccessStore | None = None) -> Access:
        """No login (loopback only); the audit log still records who traced whom from where."""
        return cls(store or AccessStore.open(":memory:"), enabled=False)

    # --- passwords -----------------------------------------------------------------------------
    def hash_password(self, password: str, name: str = "") -> str:
        """``password``'s argon2 hash for user ``name``; ``PasswordError`` if the policy refuses it
        (``password_policy``), ``HashingBusy``."""
        check_password(password, name)
        with self._hashing_slot():
            return self.hasher.hash(password)

    def verify_password(self, name: str, password: str) -> User | None:
        """The user if ``password`` is theirs; ``HashingBusy`` when all slots are taken. An unknown
        name costs as much time as a wrong password, so timing does not tell which names exist."""
        user = self.store.user(name)
        with self._hashing_slot():
            stored = user.password_hash if user is not None else self._dummy_hash()
            try:
                self.hasher.verify(stored, password)
            except (VerificationError, InvalidHashError):
                return None
        return user

    @contextmanager
    def _hashing_slot(self) -> Iterator[None]:
        if not self.hashing_slots.acquire(blocking=False):
            raise HashingBusy("the gateway is busy checking other passwords: try again in a second")
        try:
            yield
        finally:
            self.hashing_slots.release()

    def _dummy_hash(self) -> str:
        if not hasattr(self, "_dummy"):
            self._dummy = self.hasher.hash(secrets.token_urlsafe(16))
        return self._dummy

    # --- first run -----------------------------------------------------------------------------
    def prepare_setup(self) -> str | None:
        """When access control is on and there are no users: a one-time token that lets the first
        visitor holding it create an admin (``POST /api/auth/setup``); None otherwise."""
        if self.enabled and self.store.user_count() == 0:
            self.setup_token = secrets.token_urlsafe(24)
            self.setup_expires_ns = self.clock() + int(SETUP_LINK_S * NS_PER_S)
        else:
            self.setup_token = None
        return self.setup_token

    def setup_token_matches(self, token: str) -> bool:
        """Whether ``token`` is the setup token and it has not expired (``SETUP_LINK_S``)."""
        if self.setup_token is None or self.clock() >= self.setup_expires_ns:
            return False
        return hmac.compare_digest(self.setup_token.encode(), token.encode())

    # --- sessions ------------------------------------------------------------------------------
    def start_session(self, user: User) -> str:
        secret = secrets.token_urlsafe(32)
        now = self.clock()
        self.store.add_session(secret, user.name, now, now + int(self.session_s * NS_PER_S))
        return secret

    # --- who is asking -------------------------------------------------------------------------
    def principal(self, conn: HTTPConnection) -> Principal | None:
        """The user behind ``conn``: from its bearer token, ``token`` query parameter (websockets
        only) or session cookie; None if it carries none that is valid."""
        if not self.enabled:
            return Principal(LOCAL_USER, "admin", "off")
        header = conn.headers.get("authorization", "")
        scheme, _, credential = header.partition(" ")
        if scheme.lower() == "bearer" and credential.strip():
            user = self.store.token_user(credential.strip())
            return None if user is None else Principal(user.name, user.role, "token")
        if conn.scope["type"] == "websocket" and conn.query_params.get("token"):
            user = self.store.token_user(conn.query_params["token"])
            return None if user is None else Principal(user.name, user.role, "token")
        cookie = conn.cookies.get(SESSION_COOKIE)
        if cookie:
            user = self.store.session_user(cookie, self.clock())
            return None if user is None else Principal(user.name, user.role, "session")
        return None


def get_access(conn: HTTPConnection) -> Access:
    access = getattr(conn.app.state, "access", None)
    if access is None:  # an app built without access control: everything allowed
        access = Access.disabled()
        conn.app.state.access = access
    return access


AccessDep = Annotated[Access, Depends(get_access)]


class RoleRequirement:
    """A FastAPI dependency: the request's ``Principal``, if they have at least ``role``; else
    401 (no valid credential) or 403 (a role too low)."""

    def __init__(self, role: str) -> None:
        if role not in ROLES:
            raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
        self.role = role

    def __call__(self, conn: HTTPConnection) -> Principal:
        # A route may require a role on top of its router's: look the caller up once per request.
        principal = getattr(conn.state, "principal", None) or get_access(conn).principal(conn)
        if principal is None:
            raise HTTPException(401, "log in, or send an API token (Authorization: Bearer TOKEN)",
                                headers={"WWW-Authenticate": 'Bearer realm="bevflow"'})
        if not principal.can(self.role):
            raise HTTPException(403, f"this needs the {self.role} role; {principal.name} is a {principal.role}")
        conn.state.principal = principal
        return principal

    def __repr__(self) -> str:
        return f"require_role({self.role!r})"


_REQUIREMENTS = {role: RoleRequirement(role) for role in ROLES}


def require_role(role: str) -> RoleRequirement:
    """The dependency that lets only ``role`` and above through (one shared object per role)."""
    if role not in _REQUIREMENTS:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
    return _REQUIREMENTS[role]


Viewer = Annotated[Principal, Depends(require_role("viewer"))]
Operator = Annotated[Principal, Depends(require_role("operator"))]
Admin = Annotated[Principal, Depends(require_role("admin"))]


def client_address(conn: HTTPConnection) -> str:
    """Where a request came from, for the audit log and rate limiting: the address it came from, or
    the one a proxy named with ``--trusted-proxy`` forwarded (``gateway.main.proxy_options``)."""
    return conn.client.host if conn.client else "unknown"
