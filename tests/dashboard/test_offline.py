"""Pages that must work without internet, under the gateway's own Content-Security-Policy: the API
documentation (/docs, /redoc), the daily report, and the dashboard's links to the report and the
CSV exports. The browser has no network here, so anything fetched from a CDN would fail."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.dashboard.cdp import Chromium, Page
from tests.dashboard.conftest import LiveGateway


@pytest.fixture
def tab(chromium: Chromium) -> Iterator[Page]:
    page = chromium.new_page()
    try:
        yield page
    finally:
        page.close()


def test_swagger_ui_renders_from_the_gateways_own_assets(tab: Page, gateway: LiveGateway) -> None:
    tab.goto(gateway.url + "docs")
    tab.wait_for("document.querySelector('.swagger-ui .info .title')", timeout_s=20, what="Swagger UI")
    assert "bevflow gateway" in tab.evaluate("document.querySelector('.swagger-ui .info .title').textContent")
    tab.wait_for("document.querySelectorAll('.opblock').length > 10", timeout_s=20, what="the routes")
    assert tab.errors() == []


def test_redoc_renders_from_the_gateways_own_assets(tab: Page, gateway: LiveGateway) -> None:
    tab.goto(gateway.url + "redoc")
    tab.wait_for("document.querySelector('.api-content h1')", timeout_s=30, what="ReDoc")
    assert "bevflow gateway" in tab.evaluate("document.querySelector('.api-content h1').textContent")
    # ReDoc's "powered by" badge is an image on its makers' site: blocked, and nothing else missing.
    assert [e for e in tab.errors() if "cdn.redoc.ly/redoc/logo-mini.svg" not in e] == []


def test_the_daily_report_renders_styled_under_the_gateways_policy(tab: Page, gateway: LiveGateway) -> None:
    tab.goto(gateway.url + "api/reports/daily?format=html")
    tab.wait_for("document.querySelector('svg rect') && document.querySelector('th')", what="the report")
    assert tab.evaluate("getComputedStyle(document.querySelector('th')).backgroundColor") == "rgb(242, 242, 242)"
    assert tab.evaluate("getComputedStyle(document.body).marginLeft") != "8px"  # the report's margin, not the default
    fills = tab.evaluate("Array.from(document.querySelectorAll('svg rect, svg path')).map((n) => getComputedStyle(n).fill)")
    assert any(f not in ("rgb(0, 0, 0)", "none") for f in fills)  # coloured, not black blobs
    assert tab.errors() == []  # no refused style


def test_the_dashboard_links_the_report_and_the_csv_exports(page: Page) -> None:
    links = page.evaluate("Array.from(document.querySelectorAll('#exports a')).map((a) => a.href)")
    assert len(links) == 5
    assert any("format=html" in link and "tz=" in link for link in links)
    statuses = page.evaluate("Promise.all(Array.from(document.querySelectorAll('#exports a')).map("
                             "(a) => fetch(a.href).then((r) => [r.status, r.headers.get('content-type')])))")
    kinds = [kind.split(";")[0] for status, kind in statuses if status == 200]
    assert kinds.count("text/csv") >= 2 and "text/html" in kinds and "application/pdf" in kinds
