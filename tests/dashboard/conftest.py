"""Fixtures for the browser tests: one chromium and one busy gateway for the whole session, a
fresh tab per test. Every test here is skipped when chromium is not installed."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from bevflow_services.gateway import create_app

from tests.dashboard.cdp import Chromium, Page, find_chromium
from tests.dashboard.scene import Feeder, Scene
from tests.dashboard.server import serve

DASHBOARD_DIR = Path(__file__).resolve().parents[2] / "dashboard" / "bevflow_dashboard"


@pytest.fixture(scope="session")
def chromium(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Chromium]:
    executable = find_chromium()
    if executable is None:
        pytest.skip("chromium is not installed (./run test installs Debian's chromium when run as root)")
    browser = Chromium.launch(executable, tmp_path_factory.mktemp("chromium-profile"))
    try:
        yield browser
    finally:
        browser.close()


@dataclass
class LiveGateway:
    scene: Scene
    url: str


@pytest.fixture(scope="session")
def gateway() -> Iterator[LiveGateway]:
    """The dashboard over a hall with 44 people, ticking five times a second."""
    scene = Scene.build()
    app = create_app(scene.site, scene.state, dashboard_dir=DASHBOARD_DIR)
    with Feeder(scene), serve(app) as port:
        yield LiveGateway(scene, f"http://127.0.0.1:{port}/")


def open_dashboard(chromium: Chromium, url: str) -> Page:
    page = chromium.new_page()
    page.goto(url)
    page.wait_for("window.bevflow && window.bevflow.ready && window.bevflow.people > 0", timeout_s=10, what="the dashboard to go live")
    return page


def alert_node(alert_id: str) -> str:
    """JavaScript for the alert feed's list item of ``alert_id``."""
    return f"document.querySelector('#alert-list [data-id={json.dumps(alert_id)}]')"


@pytest.fixture
def page(chromium: Chromium, gateway: LiveGateway) -> Iterator[Page]:
    page = open_dashboard(chromium, gateway.url)
    try:
        yield page
    finally:
        page.close()
