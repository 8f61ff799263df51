"""The dashboard's files over a real server, with paths sent exactly as written (no client
normalises them): every spelling of a page needs its role; only the allow-list is public."""

from __future__ import annotations

import http.client

import pytest

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.app import DASHBOARD_DIR
from tests.services.gateway.access import secured_access
from tests.services.gateway.live import serve_in_thread

# (path as sent, what an anonymous visitor gets: "login" is the redirect to the login page)
ANONYMOUS = [
    ("/", "login"),
    ("/index.html", "login"),
    ("/./index.html", "login"),
    ("//index.html", "login"),
    ("/index.html/", "login"),
    ("/%2e/index.html", "login"),
    ("/calibration.html", "login"),
    ("/calibration.html/", "login"),
    ("/.//calibration.html", "login"),
    ("/login.html", 200),
    ("/style.css", 200),
    ("/js/main.js", 200),
    ("/./js/main.js", 200),
    ("/__init__.py", 404),
    ("/js/../__init__.py", 404),
    ("/..%2f__init__.py", 404),
    ("/missing.css", 404),
    ("/api/nothing-here", 404),
]


def get(address: str, path: str, headers: dict[str, str] | None = None) -> tuple[int, str]:
    host, port = address.split(":")
    connection = http.client.HTTPConnection(host, int(port), timeout=10)
    try:
        connection.request("GET", path, headers=headers or {})
        response = connection.getresponse()
        response.read()
        return response.status, response.getheader("location") or ""
    finally:
        connection.close()


@pytest.fixture
def gateway(site: Site, state: GatewayState):
    access, tokens = secured_access()
    with serve_in_thread(create_app(site, state, dashboard_dir=DASHBOARD_DIR, access=access)) as address:
        yield address, tokens


@pytest.mark.parametrize(("path", "outcome"), ANONYMOUS, ids=[p for p, _ in ANONYMOUS])
def test_no_spelling_of_a_page_skips_the_login(gateway, path: str, outcome) -> None:
    address, _ = gateway
    status, location = get(address, path)
    if outcome == "login":
        assert status == 303 and location.startswith("/login.html?next=")
    else:
        assert status == outcome


@pytest.mark.parametrize("path", ["/calibration.html/", "//calibration.html"])
def test_a_page_spelt_differently_still_needs_its_role(gateway, path: str) -> None:
    address, tokens = gateway
    assert get(address, path, {"Authorization": f"Bearer {tokens['viewer']}"})[0] == 403
    assert get(address, path, {"Authorization": f"Bearer {tokens['admin']}"})[0] == 200
