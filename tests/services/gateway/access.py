"""A gateway with access control on: one user per role, each with a password and an API token."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from argon2 import PasswordHasher
from fastapi import FastAPI
from fastapi.testclient import TestClient

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.auth import Access
from bevflow_services.gateway.auth_limits import LoginLimiter
from bevflow_services.storage.access import ROLES, AccessStore

PASSWORD = "correct horse battery"  # every test user's
CHEAP_HASHER = PasswordHasher(time_cost=1, memory_cost=8, parallelism=1)  # tests: fast, same format


@dataclass
class Secured:
    app: FastAPI
    access: Access
    tokens: dict[str, str]  # role -> API token of that role's user (named after the role)


def secured_access(url: str = ":memory:", limiter: LoginLimiter | None = None, **options: object) -> tuple[Access, dict[str, str]]:
    access = Access(AccessStore.open(url), hasher=CHEAP_HASHER, limiter=limiter or LoginLimiter(), **options)  # type: ignore[arg-type]
    tokens = {}
    for role in ROLES:
        access.store.add_user(role, role, access.hash_password(PASSWORD), access.clock())
        tokens[role] = f"token-of-{role}"
        access.store.add_token(tokens[role], role, "tests", access.clock())
    return access, tokens


@contextmanager
def secured_client(site: Site, state: GatewayState, url: str = ":memory:", **options: object) -> Iterator[tuple[TestClient, Secured]]:
    access, tokens = secured_access(url, **options)  # type: ignore[arg-type]
    app = create_app(site, state, access=access)
    try:
        with TestClient(app) as client:
            yield client, Secured(app, access, tokens)
    finally:
        access.store.close()


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}
