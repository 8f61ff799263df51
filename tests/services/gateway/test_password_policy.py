"""The password policy, and what the gateway does with it: a setup link that expires, and wrong
tries from one address that do not lock the owner out from another."""

from __future__ import annotations

import pytest

from bevflow.site import Site
from bevflow.units import NS_PER_S

from bevflow_services.gateway import GatewayState
from bevflow_services.gateway.auth import SETUP_LINK_S
from bevflow_services.gateway.password_policy import PasswordError, check_password
from tests.services.gateway.access import PASSWORD, secured_client


@pytest.mark.parametrize(("password", "name", "refusal"), [
    ("correct horse battery", "ana", None),
    ("Tr0ub4dor&3x", "", None),
    ("short", "", "at least 10 characters"),
    ("aaaaaaaaaa", "", "at least 4 different characters"),
    ("abababababab", "", "at least 4 different characters"),
    ("1234567890", "", "first that anyone guessing"),
    ("Password123", "", "first that anyone guessing"),
    ("QWERTYUIOP", "", "first that anyone guessing"),
    ("Ana-is-the-best", "ana", "the user's name"),
])
def test_the_password_policy(password: str, name: str, refusal: str | None) -> None:
    if refusal is None:
        assert check_password(password, name) == password
    else:
        with pytest.raises(PasswordError, match=refusal):
            check_password(password, name)


@pytest.mark.parametrize("password", ["aaaaaaaaaa", "password123", "viewer-viewer-1"])
def test_weak_passwords_are_refused_over_rest(site: Site, state: GatewayState, password: str) -> None:
    with secured_client(site, state) as (client, secure):
        client.post("/api/auth/login", json={"name": "admin", "password": PASSWORD})
        made = client.post("/api/users", json={"name": "night", "role": "viewer", "password": password.replace("viewer", "night")})
        assert made.status_code == 400


def test_the_setup_link_expires(site: Site, state: GatewayState) -> None:
    now = [1_000 * NS_PER_S]
    with secured_client(site, state, clock=lambda: now[0]) as (client, secure):
        for user in secure.access.store.users():
            secure.access.store.remove_user(user.name)
        token = secure.access.prepare_setup()
        now[0] += int(SETUP_LINK_S * NS_PER_S)
        late = client.post("/api/auth/setup", json={"token": token, "name": "root", "password": "long enough pw"})
        assert late.status_code == 403
        assert secure.access.store.user_count() == 0


def test_wrong_tries_from_elsewhere_do_not_lock_the_owner_out(site: Site, state: GatewayState) -> None:
    with secured_client(site, state) as (client, secure):
        for _ in range(secure.access.limiter.max_failures):  # someone guessing from another address
            assert secure.access.limiter.attempt("viewer", "198.51.100.7") == 0
        assert secure.access.limiter.attempt("viewer", "198.51.100.7") > 0  # they are locked out
        owner = client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
        assert owner.status_code == 200  # the owner, from their own address, is not
