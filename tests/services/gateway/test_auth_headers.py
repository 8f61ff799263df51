"""Security headers on every response, CORS for configured origins only, and the dashboard pages'
redirect to the login page."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.auth_headers import content_security_policy
from tests.services.gateway.access import PASSWORD, bearer, secured_client


@pytest.fixture
def secured(site: Site, state: GatewayState):
    with secured_client(site, state) as pair:
        yield pair


@pytest.mark.parametrize("path", ["/", "/login.html", "/js/login.js", "/api/health", "/api/occupancy", "/no-such-file"])
def test_every_response_carries_the_security_headers(secured, path: str) -> None:
    client, _ = secured
    response = client.get(path, follow_redirects=False)
    assert response.headers["x-content-type-options"] == "nosniff"
    assert response.headers["referrer-policy"] == "no-referrer"
    assert response.headers["x-frame-options"] == "DENY"
    policy = response.headers["content-security-policy"]
    assert "frame-ancestors 'none'" in policy
    assert "script-src 'self';" in policy  # the dashboard's modules only: no inline script, no eval
    assert "strict-transport-security" not in response.headers  # plain HTTP here


def test_the_3d_view_may_be_framed_by_the_gateways_own_pages_only() -> None:
    assert "frame-src 'self';" in content_security_policy("/")  # the dashboard frames /view3d/, nothing else
    view = content_security_policy("/view3d/")
    assert "frame-ancestors 'self'" in view and "http" not in view  # framed by no other site


def test_the_api_docs_get_a_policy_that_lets_swagger_load_from_the_gateway_only(secured) -> None:
    client, _ = secured
    page = client.get("/docs")
    policy = page.headers["content-security-policy"]
    assert "http" not in policy and "frame-ancestors 'none'" in policy  # no other origin at all
    assert "http" not in page.text.replace('"/openapi.json"', "")  # every asset from the gateway
    for path in ("/docs-assets/swagger-ui-bundle.js", "/docs-assets/swagger-ui.css", "/docs-assets/redoc.standalone.js"):
        assert path.split("/")[-1] in page.text + client.get("/redoc").text
        assert client.get(path).status_code == 200


@pytest.mark.parametrize(
    ("origins", "origin", "allowed"),
    [
        ((), "https://evil.example", False),
        ((), "https://ops.example", False),
        (("https://ops.example",), "https://ops.example", True),
        (("https://ops.example",), "https://evil.example", False),
    ],
)
def test_cors_answers_only_configured_origins(site: Site, state: GatewayState, origins, origin: str, allowed: bool) -> None:
    with secured_client(site, state, cors_origins=origins) as (client, secure):
        simple = client.get("/api/occupancy", headers={"Origin": origin, **bearer(secure.tokens["viewer"])})
        assert simple.status_code == 200
        assert simple.headers.get("access-control-allow-origin") == (origin if allowed else None)
        preflight = client.options("/api/occupancy", headers={
            "Origin": origin, "Access-Control-Request-Method": "GET", "Access-Control-Request-Headers": "authorization"})
        assert (preflight.headers.get("access-control-allow-origin") == origin) == allowed
        assert "access-control-allow-credentials" not in preflight.headers  # tokens, never cookies, cross-site


@pytest.mark.parametrize(
    ("page", "who", "status", "location"),
    [
        ("/", None, 303, "/login.html?next=/"),
        ("/index.html", None, 303, "/login.html?next=/"),
        ("/calibration.html", None, 303, "/login.html?next=/calibration.html"),
        ("/", "viewer", 200, None),
        ("/calibration.html", "operator", 403, None),
        ("/calibration.html", "admin", 200, None),
        ("/login.html", None, 200, None),
    ],
)
def test_dashboard_pages_need_a_login(secured, page: str, who: str | None, status: int, location: str | None) -> None:
    client, _ = secured
    if who is not None:
        assert client.post("/api/auth/login", json={"name": who, "password": PASSWORD}).status_code == 200
    response = client.get(page, follow_redirects=False)
    assert response.status_code == status
    assert response.headers.get("location") == location
    if status == 403:
        assert "needs the admin role" in response.text


def test_logout_page_ends_the_session_and_shows_the_login(secured) -> None:
    client, _ = secured
    client.post("/api/auth/login", json={"name": "viewer", "password": PASSWORD})
    response = client.get("/logout", follow_redirects=False)
    assert response.status_code == 303 and response.headers["location"] == "/login.html?logged_out=1"
    assert client.get("/api/auth/me").status_code == 401


def test_without_access_control_everything_is_open_as_the_local_admin(site: Site, state: GatewayState) -> None:
    with TestClient(create_app(site, state)) as client:
        assert client.get("/", follow_redirects=False).status_code == 200
        assert client.get("/api/auth/me").json() == {"name": "local", "role": "admin", "via": "off", "auth": False}
        refused = client.post("/api/auth/login", json={"name": "x", "password": "y"})
        assert refused.status_code == 400 and "access control is off" in refused.json()["detail"]
        client.get("/api/tracks/7")  # tracing is still audited, as the local admin
        entries = client.get("/api/audit").json()["items"]
        assert [(e["user"], e["action"], e["track_id"]) for e in entries] == [("local", "trajectory", 7)]
