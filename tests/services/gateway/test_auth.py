"""Access control through the app: every route's role, tokens and session cookies, websockets,
login rate limiting, first-run setup and ``--auth`` checks."""

from __future__ import annotations

import pytest
from starlette.testclient import WebSocketDenialResponse

from bevflow.site import Site

from bevflow_services.gateway import GatewayState
from bevflow_services.gateway.auth import SESSION_COOKIE, check_auth_mode, is_loopback, require_role
from bevflow_services.gateway.auth_limits import LoginLimiter
from tests.services.gateway.access import PASSWORD, bearer, secured_client
from tests.services.gateway.feed import S, T0, tracks
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

# The lowest role each route needs; "public" answers anyone. Every route of the app is listed:
# a new route fails test_every_route_is_in_the_table until it is given a role here.
ROUTE_ROLES = {
    ("GET", "/api/occupancy"): "viewer",
    ("GET", "/api/occupancy/history"): "viewer",
    ("GET", "/api/intervals"): "viewer",
    ("GET", "/api/tracks"): "viewer",
    ("GET", "/api/tracks/{track_id}"): "operator",
    ("GET", "/api/tracks/{track_id}/contacts"): "operator",
    ("GET", "/api/violations"): "viewer",
    ("GET", "/api/alerts"): "viewer",
    ("GET", "/api/incidents"): "viewer",
    ("GET", "/api/cameras"): "viewer",
    ("GET", "/api/cameras/{camera_id}"): "viewer",
    ("GET", "/api/site"): "viewer",
    ("GET", "/api/config"): "viewer",
    ("GET", "/api/history/occupancy"): "viewer",
    ("GET", "/api/history/events"): "viewer",
    ("GET", "/api/history/tracks"): "operator",
    ("GET", "/api/reports/daily"): "viewer",
    ("GET", "/api/calibration"): "admin",
    ("GET", "/api/calibration/cameras/{camera_id}/frame"): "admin",
    ("POST", "/api/calibration/cameras/{camera_id}/solve"): "admin",
    ("PUT", "/api/calibration/cameras/{camera_id}/extrinsics"): "admin",
    ("GET", "/api/calibration/consistency"): "admin",
    ("GET", "/api/calibration/drift"): "admin",
    ("GET", "/api/health"): "public",
    ("GET", "/healthz"): "public",
    ("GET", "/readyz"): "public",
    ("POST", "/api/alerts/{alert_id}/acknowledge"): "operator",
    ("POST", "/api/alerts/acknowledge"): "operator",
    ("GET", "/api/acknowledgements"): "viewer",
    ("POST", "/api/auth/login"): "public",
    ("POST", "/api/auth/logout"): "public",
    ("GET", "/api/auth/me"): "viewer",
    ("POST", "/api/auth/setup"): "public",
    ("GET", "/api/users"): "admin",
    ("POST", "/api/users"): "admin",
    ("DELETE", "/api/users/{name}"): "admin",
    ("POST", "/api/users/{name}/tokens"): "admin",
    ("GET", "/api/users/{name}/tokens"): "admin",
    ("DELETE", "/api/users/{name}/tokens/{token_id}"): "admin",
    ("PUT", "/api/users/{name}/password"): "admin",
    ("PUT", "/api/users/{name}/role"): "admin",
    ("GET", "/api/audit"): "admin",
}
CALLERS = ("anonymous", "viewer", "operator", "admin")
RANK = {"public": -1, "anonymous": -1, "viewer": 0, "operator": 1, "admin": 2}


def expected_status(needed: str, caller: str) -> str:
    if RANK[caller] >= RANK[needed]:
        return "allowed"
    return "401" if caller == "anonymous" else "403"


def concrete(path: str) -> str:
    return path.replace("{track_id}", "1").replace("{camera_id}", "no-such-camera").replace(
        "{alert_id}", "no-such-alert").replace("{name}", "no-such-user").replace("{token_id}", "999")


@pytest.fixture
def secured(site: Site, state: GatewayState):
    with secured_client(site, state) as pair:
        yield pair


def test_every_route_is_in_the_table(secured) -> None:
    client, _ = secured
    spec = client.get("/openapi.json").json()
    routes = {(method.upper(), path) for path, ops in spec["paths"].items() for method in ops}
    assert routes == set(ROUTE_ROLES)


@pytest.mark.parametrize("caller", CALLERS)
def test_each_role_reaches_exactly_its_routes(secured, caller: str) -> None:
    client, secure = secured
    headers = {} if caller == "anonymous" else bearer(secure.tokens[caller])
    outcomes = {}
    for method, path in ROUTE_ROLES:
        if path == "/api/auth/logout":
            continue  # it would end nothing here, but keep the matrix free of side effects on the client
        response = client.request(method, concrete(path), headers=headers)
        code = response.status_code
        outcomes[(method, path)] = str(code) if code in (401, 403) else "allowed"
    expected = {key: expected_status(needed, caller) for key, needed in ROUTE_ROLES.items() if key[1] != "/api/auth/logout"}
    assert outcomes == expected


def test_refusals_say_what_is_missing(secured) -> None:
    client, secure = secured
    anonymous = client.get("/api/occupancy")
    assert anonymous.status_code == 401
    assert anonymous.headers["www-authenticate"].startswith("Bearer")
    assert "log in" in anonymous.json()["detail"]
    viewer = client.get("/api/tracks/1", headers=bearer(secure.tokens["viewer"]))
    assert viewer.json()["detail"] == "this needs the operator role; viewer is a viewer"


@pytest.mark.parametrize("header", ["Bearer nonsense", "Bearer ", "Basic dmlld2VyOnBhc3M=", "bearer token-of-admin "])
def test_only_a_valid_bearer_token_counts(secured, header: str) -> None:
    client, _ = secured
    status = client.get("/api/occupancy", headers={"Authorization": header}).status_code
    assert status == (200 if header.strip().endswith("token-of-admin") else 401)


def test_a_session_cookie_from_login_works_until_logout(secured) -> None:
    client, _ = secured
    login = client.post("/api/auth/login", json={"name": "operator", "password": PASSWORD})
    assert login.status_code == 200
    assert login.json() == {"name": "operator", "role": "operator", "via": "session", "auth": True}
    cookie = login.headers["set-cookie"]
    assert "HttpOnly" in cookie and "SameSite=strict" in cookie and "Secure" not in cookie and "Path=/" in cookie
    assert client.get("/api/auth/me").json()["name"] == "operator"
    assert client.get("/api/tracks/1").status_code == 404  # allowed: an operator route, no such track
    assert client.post("/api/auth/logout").status_code == 204
    assert client.get("/api/auth/me").status_code == 401


def test_the_cookie_is_secure_over_tls(site: Site, state: GatewayState) -> None:
    with secured_client(site, state, secure_cookies=True) as (client, _):
        login = client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
        assert "Secure" in login.headers["set-cookie"]
        assert login.headers["strict-transport-security"].startswith("max-age=")


def test_a_forged_or_expired_session_is_refused(secured) -> None:
    client, secure = secured
    client.cookies.set(SESSION_COOKIE, "made-up")
    assert client.get("/api/auth/me").status_code == 401
    client.cookies.clear()
    client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
    assert client.get("/api/auth/me").status_code == 200
    later = secure.access.clock() + 12 * 3600 * S + S  # a second past the 12 h a session lasts
    secure.access.clock = lambda: later
    assert client.get("/api/auth/me").status_code == 401


@pytest.mark.parametrize(
    ("name", "password", "status"),
    [("viewer", PASSWORD, 200), ("viewer", "wrong password", 401), ("nobody", PASSWORD, 401), ("VIEWER", PASSWORD, 401)],
)
def test_login_needs_the_right_name_and_password(secured, name: str, password: str, status: int) -> None:
    client, _ = secured
    response = client.post("/api/auth/login", json={"name": name, "password": password})
    assert response.status_code == status
    assert (SESSION_COOKIE in response.headers.get("set-cookie", "")) == (status == 200)
    if status == 401:
        assert response.json()["detail"] == "wrong user name or password"  # the same whichever was wrong


def test_repeated_failures_are_rate_limited_per_name_and_address(site: Site, state: GatewayState) -> None:
    now = [0.0]
    limiter = LoginLimiter(max_failures=3, window_s=60.0, clock=lambda: now[0])
    with secured_client(site, state, limiter=limiter) as (client, _):
        def attempt(name: str, password: str) -> int:
            return client.post("/api/auth/login", json={"name": name, "password": password}).status_code

        assert [attempt("viewer", "nope") for _ in range(3)] == [401, 401, 401]
        now[0] = 20.0
        refused = client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
        assert refused.status_code == 429  # even the right password, while locked
        assert refused.headers["retry-after"] == "40"
        assert "try again in 40 s" in refused.json()["detail"]
        assert attempt("operator", PASSWORD) == 200  # another name is not locked
        now[0] = 60.5
        assert attempt("viewer", PASSWORD) == 200
        assert attempt("viewer", "nope") == 401  # success cleared the count


@pytest.mark.parametrize(("host", "ok"), [("127.0.0.1", True), ("::1", True), ("localhost", True), ("127.0.0.2", True),
                                          ("0.0.0.0", False), ("192.168.1.4", False), ("::", False), ("gateway.local", False)])
def test_auth_off_only_on_loopback(host: str, ok: bool) -> None:
    assert is_loopback(host) == ok
    check_auth_mode("on", host)
    if ok:
        check_auth_mode("off", host)
    else:
        with pytest.raises(ValueError, match="only allowed when serving on loopback"):
            check_auth_mode("off", host)


def test_require_role_rejects_unknown_roles() -> None:
    assert require_role("admin").role == "admin"
    with pytest.raises(ValueError, match="role must be one of viewer, operator, admin"):
        require_role("root")


# --- websockets ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("path", "how", "outcome"),
    [
        ("/ws/tracks", "none", 401),
        ("/ws/tracks", "bad-token", 401),
        ("/ws/tracks", "query-token", "open"),
        ("/ws/tracks", "header-token", "open"),
        ("/ws/tracks", "cookie", "open"),
        ("/ws/alerts?replay=active", "none", 401),
        ("/ws/alerts?replay=active", "query-token", "open"),
        ("/ws/acknowledgements", "none", 401),
        ("/ws/acknowledgements", "cookie", "open"),
    ],
)
def test_websockets_need_a_token_or_a_session(secured, state: GatewayState, path: str, how: str, outcome) -> None:
    client, secure = secured
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    headers = {}
    if how == "cookie":
        client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
    elif how == "header-token":
        headers = bearer(secure.tokens["viewer"])
    elif how in ("query-token", "bad-token"):
        token = secure.tokens["viewer"] if how == "query-token" else "nonsense"
        path += ("&" if "?" in path else "?") + f"token={token}"
    if outcome == "open":
        with client.websocket_connect(path, headers=headers) as ws:
            if path.startswith("/ws/tracks"):
                assert ws.receive_json()["time_ns"] == T0
            ws.close()
    else:
        with pytest.raises(WebSocketDenialResponse) as refused:
            with client.websocket_connect(path, headers=headers):
                pass
        assert refused.value.status_code == outcome


# --- first run -----------------------------------------------------------------------------------
def test_the_first_admin_is_made_once_with_the_setup_token(site: Site, state: GatewayState) -> None:
    with secured_client(site, state) as (client, secure):
        store = secure.access.store
        for user in store.users():
            store.remove_user(user.name)
        token = secure.access.prepare_setup()
        assert token is not None and len(token) >= 24
        wrong = client.post("/api/auth/setup", json={"token": "guess", "name": "root", "password": "long enough pw"})
        assert wrong.status_code == 403
        short = client.post("/api/auth/setup", json={"token": token, "name": "root", "password": "short"})
        assert short.status_code == 400 and "at least 10 characters" in short.json()["detail"]
        made = client.post("/api/auth/setup", json={"token": token, "name": "root", "password": "long enough pw"})
        assert made.status_code == 201 and made.json()["role"] == "admin"
        assert client.get("/api/users").status_code == 200  # logged in as the new admin
        again = client.post("/api/auth/setup", json={"token": token, "name": "evil", "password": "long enough pw"})
        assert again.status_code == 403
        assert [(u.name, u.role) for u in store.users()] == [("root", "admin")]
        assert secure.access.prepare_setup() is None  # users exist: no setup link on the next start


# --- both databases ------------------------------------------------------------------------------
def test_tokens_sessions_and_audit_on_each_database(site: Site, state: GatewayState, database_url: str) -> None:  # noqa: F811
    state.apply(tracks(T0, {4: (0.0, 0.0)}))
    state.apply(tracks(T0 + S, {4: (0.5, 0.0)}))
    with secured_client(site, state, url=database_url) as (client, secure):
        assert client.get("/api/tracks/4", headers=bearer(secure.tokens["operator"])).status_code == 200
        client.post("/api/auth/login", json={"name": "admin", "password": PASSWORD})
        assert client.get("/api/tracks/4/contacts?distance_m=1.5").status_code == 200
        log = client.get("/api/audit").json()
        assert log["total"] == 2
        assert [(e["user"], e["action"], e["track_id"], e["client"]) for e in log["items"]] == [
            ("admin", "contacts", 4, "testclient"), ("operator", "trajectory", 4, "testclient")]
        assert log["items"][0]["detail"] == "distance_m=1.5"


def test_guessing_across_many_names_from_one_address_is_limited_too(site: Site, state: GatewayState) -> None:
    now = [0.0]
    with secured_client(site, state) as (client, secure):
        secure.access.address_limiter = LoginLimiter(max_failures=4, window_s=60.0, clock=lambda: now[0])
        codes = [client.post("/api/auth/login", json={"name": f"user{k}", "password": "guess"}).status_code for k in range(4)]
        assert codes == [401, 401, 401, 401]
        refused = client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
        assert (refused.status_code, refused.headers["retry-after"]) == (429, "60")
        now[0] = 61.0
        assert client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD}).status_code == 200


@pytest.mark.parametrize(("origin", "opens"), [(None, True), ("http://testserver", True), ("https://evil.example", False)])
def test_a_session_socket_must_come_from_the_gateways_own_pages(secured, origin: str | None, opens: bool) -> None:
    client, secure = secured
    client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
    headers = {} if origin is None else {"Origin": origin}
    if opens:
        with client.websocket_connect("/ws/acknowledgements", headers=headers) as ws:
            ws.close()
    else:
        with pytest.raises(WebSocketDenialResponse) as refused:
            with client.websocket_connect("/ws/acknowledgements", headers=headers):
                pass
        assert refused.value.status_code == 403
    # a token is not ambient: it may come from anywhere CORS allows
    with client.websocket_connect(f"/ws/acknowledgements?token={secure.tokens['viewer']}",
                                  headers={"Origin": "https://evil.example"}) as ws:
        ws.close()
