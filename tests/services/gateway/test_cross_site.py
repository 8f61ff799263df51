"""Other sites' pages cannot act through the user's browser: with access control off only loopback
Host names are answered (DNS rebinding) and only the gateway's own pages may change things; with it
on, a request whose rights come from the session cookie must come from the gateway's own pages."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.auth import Access
from bevflow_services.storage.access import AccessStore
from tests.services.gateway.access import PASSWORD, bearer, secured_client

LOCAL = "127.0.0.1:8000"
EVIL = "http://evil.example"
ACKNOWLEDGE = "/api/alerts/no-such-alert/acknowledge"  # 404 once let through


@pytest.fixture
def auth_off(site: Site, state: GatewayState):
    access = Access(AccessStore.open(":memory:"), enabled=False, loopback_only=True)
    with TestClient(create_app(site, state, access=access)) as client:
        yield client


@pytest.mark.parametrize(("method", "path", "headers", "refused"), [
    ("GET", "/api/occupancy", {"Host": LOCAL}, False),
    ("GET", "/api/occupancy", {"Host": "localhost:8000"}, False),
    ("GET", "/api/occupancy", {"Host": "[::1]:8000"}, False),
    ("GET", "/api/occupancy", {"Host": "127.0.0.1"}, False),
    ("GET", "/api/occupancy", {"Host": "evil.example:8000"}, True),      # a rebound name
    ("GET", "/api/occupancy", {"Host": "127.0.0.1.evil.example"}, True),
    ("GET", "/", {"Host": "evil.example"}, True),
    ("POST", ACKNOWLEDGE, {"Host": LOCAL}, False),                        # curl: no Origin
    ("POST", ACKNOWLEDGE, {"Host": LOCAL, "Origin": f"http://{LOCAL}"}, False),
    ("POST", ACKNOWLEDGE, {"Host": LOCAL, "Origin": EVIL}, True),         # another site's form
    ("POST", ACKNOWLEDGE, {"Host": LOCAL, "Origin": "null"}, True),
    ("POST", ACKNOWLEDGE, {"Host": LOCAL, "Sec-Fetch-Site": "cross-site"}, True),
    ("POST", ACKNOWLEDGE, {"Host": LOCAL, "Origin": "http://127.0.0.1:9999"}, True),
])
def test_with_access_control_off_only_this_machine_and_its_pages_are_answered(
        auth_off: TestClient, method: str, path: str, headers: dict[str, str], refused: bool) -> None:
    response = auth_off.request(method, path, headers=headers, follow_redirects=False)
    assert (response.status_code == 403) == refused, response.text


@pytest.mark.parametrize(("headers", "opens"), [
    ({"Host": LOCAL}, True),
    ({"Host": LOCAL, "Origin": f"http://{LOCAL}"}, True),
    ({"Host": LOCAL, "Origin": EVIL}, False),
    ({"Host": "evil.example:8000", "Origin": "http://evil.example:8000"}, False),
])
def test_with_access_control_off_sockets_open_only_from_its_pages(auth_off: TestClient, headers, opens: bool) -> None:
    if opens:
        with auth_off.websocket_connect("/ws/acknowledgements", headers=headers) as ws:
            ws.close()
    else:
        with pytest.raises(WebSocketDenialResponse):
            with auth_off.websocket_connect("/ws/acknowledgements", headers=headers):
                pass


@pytest.mark.parametrize(("credential", "headers", "status"), [
    ("cookie", {}, 201),
    ("cookie", {"Origin": "http://testserver"}, 201),
    ("cookie", {"Origin": EVIL}, 403),                                  # CSRF with the admin's cookie
    ("cookie", {"Origin": EVIL, "Content-Type": "application/x-www-form-urlencoded"}, 403),
    ("cookie", {"Sec-Fetch-Site": "cross-site"}, 403),
    ("token", {"Origin": EVIL}, 201),                                   # a token is not sent by itself
])
def test_with_access_control_on_the_cookie_acts_only_from_the_gateways_pages(
        site: Site, state: GatewayState, credential: str, headers: dict[str, str], status: int) -> None:
    with secured_client(site, state) as (client, secure):
        if credential == "cookie":
            assert client.post("/api/auth/login", json={"name": "admin", "password": PASSWORD}).status_code == 200
        else:
            headers = {**headers, **bearer(secure.tokens["admin"])}
        response = client.post("/api/users/viewer/tokens", headers=headers)
        assert response.status_code == status, response.text
        assert client.get("/api/users", headers={"Origin": EVIL}).status_code == (200 if credential == "cookie" else 401)
