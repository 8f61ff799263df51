"""``/api/users`` and ``/api/audit``: an admin manages accounts and tokens and reads who traced whom."""

from __future__ import annotations

import pytest

from bevflow.site import Site

from bevflow_services.gateway import GatewayState
from tests.services.gateway.access import bearer, secured_client
from tests.services.gateway.feed import S, T0, tracks


@pytest.fixture
def admin_client(site: Site, state: GatewayState):
    with secured_client(site, state) as (client, secure):
        client.headers.update(bearer(secure.tokens["admin"]))
        yield client, secure


def test_an_admin_adds_a_user_who_can_then_log_in(admin_client) -> None:
    client, _ = admin_client
    made = client.post("/api/users", json={"name": "night", "role": "operator", "password": "a long password"})
    assert made.status_code == 201 and made.json()["role"] == "operator"
    assert [(u["name"], u["role"]) for u in client.get("/api/users").json()] == [
        ("admin", "admin"), ("night", "operator"), ("operator", "operator"), ("viewer", "viewer")]
    client.headers.pop("Authorization")
    assert client.post("/api/auth/login", json={"name": "night", "password": "a long password"}).json()["role"] == "operator"


@pytest.mark.parametrize(
    ("body", "status", "detail"),
    [
        ({"name": "viewer", "role": "viewer", "password": "a long password"}, 409, "already exists"),
        ({"name": "x", "role": "root", "password": "a long password"}, 400, "role 'root'"),
        ({"name": "x", "role": "viewer", "password": "short"}, 400, "at least 10 characters"),
        ({"name": "a:b", "role": "viewer", "password": "a long password"}, 400, "user name"),
    ],
)
def test_bad_new_users_are_refused(admin_client, body: dict, status: int, detail: str) -> None:
    client, _ = admin_client
    response = client.post("/api/users", json=body)
    assert response.status_code == status
    assert detail in response.json()["detail"]


def test_removing_a_user_revokes_their_token(admin_client) -> None:
    client, secure = admin_client
    assert client.delete("/api/users/viewer").status_code == 204
    assert client.get("/api/occupancy", headers=bearer(secure.tokens["viewer"])).status_code == 401
    assert client.delete("/api/users/viewer").status_code == 404
    assert client.delete("/api/users/admin").status_code == 400  # not yourself


def test_a_token_made_for_a_user_is_shown_once_and_works(admin_client) -> None:
    client, _ = admin_client
    made = client.post("/api/users/viewer/tokens", json={"label": "lobby screen"})
    assert made.status_code == 201
    token = made.json()["token"]
    assert token.startswith("bvf_") and len(token) == 4 + 43
    assert client.get("/api/auth/me", headers=bearer(token)).json()["name"] == "viewer"
    assert client.post("/api/users/nobody/tokens", json={}).status_code == 404


def test_tracing_is_audited_with_who_what_and_where(admin_client, state: GatewayState) -> None:
    client, secure = admin_client
    state.apply(tracks(T0, {3: (0.0, 0.0), 5: (1.0, 0.0)}))
    state.apply(tracks(T0 + S, {3: (0.0, 0.0), 5: (1.0, 0.0)}))
    operator = bearer(secure.tokens["operator"])
    assert client.get("/api/tracks/3", headers=operator).status_code == 200
    assert client.get("/api/tracks/5/contacts", headers=operator).status_code == 200
    assert client.get("/api/tracks/404", headers=operator).status_code == 404  # a look for someone unknown counts too
    assert client.get("/api/tracks").status_code == 200  # where everyone is: audited as the live stream is
    log = client.get("/api/audit").json()
    assert [(e["user"], e["action"], e["track_id"]) for e in log["items"]] == [
        ("admin", "live_tracks", None), ("operator", "trajectory", 404), ("operator", "contacts", 5), ("operator", "trajectory", 3)]
    assert {e["client"] for e in log["items"]} == {"testclient"}
    assert [e["track_id"] for e in client.get("/api/audit?track=5").json()["items"]] == [5]
    assert client.get("/api/audit?user=admin").json()["total"] == 1
    page = client.get("/api/audit?limit=1&offset=2").json()
    assert (page["total"], [e["track_id"] for e in page["items"]]) == (4, [5])


def test_an_admin_lists_and_revokes_a_users_tokens(admin_client) -> None:
    client, secure = admin_client
    made = client.post("/api/users/viewer/tokens", json={"label": "lobby screen"}).json()
    listed = client.get("/api/users/viewer/tokens").json()
    assert [(t["label"], t["token"]) for t in listed] == [("tests", None), ("lobby screen", None)]  # never the secret
    assert client.delete(f"/api/users/operator/tokens/{made['id']}").status_code == 404  # not operator's
    assert client.delete(f"/api/users/viewer/tokens/{made['id']}").status_code == 204
    assert client.get("/api/occupancy", headers=bearer(made["token"])).status_code == 401
    assert client.get("/api/occupancy", headers=bearer(secure.tokens["viewer"])).status_code == 200  # the other stays
    assert client.get("/api/users/nobody/tokens").status_code == 404


def test_a_new_password_ends_sessions_and_tokens(admin_client) -> None:
    client, secure = admin_client
    assert client.put("/api/users/viewer/password", json={"password": "aaaaaaaaaaaa"}).status_code == 400
    assert client.put("/api/users/viewer/password", json={"password": "a fresh passphrase"}).status_code == 204
    assert client.get("/api/occupancy", headers=bearer(secure.tokens["viewer"])).status_code == 401
    client.headers.pop("Authorization")
    assert client.post("/api/auth/login", json={"name": "viewer", "password": "a fresh passphrase"}).status_code == 200


@pytest.mark.parametrize(("name", "role", "status"), [
    ("viewer", "operator", 200), ("operator", "viewer", 200), ("viewer", "root", 400), ("nobody", "viewer", 404),
    ("admin", "viewer", 400),  # not your own
])
def test_an_admin_changes_a_role(admin_client, name: str, role: str, status: int) -> None:
    client, secure = admin_client
    response = client.put(f"/api/users/{name}/role", json={"role": role})
    assert response.status_code == status, response.text
    if status == 200:
        assert response.json()["role"] == role
        needs_operator = client.get("/api/tracks/1", headers=bearer(secure.tokens[name])).status_code
        assert (needs_operator != 403) == (role == "operator")
