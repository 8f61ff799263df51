"""The dashboard is honest about degraded data: a stopped camera and late ticks show as such, and
the map and the occupancy panel always show the same tick."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from bevflow_services.gateway import create_app

from tests.dashboard.cdp import Chromium, Page
from tests.dashboard.conftest import DASHBOARD_DIR, LiveGateway, open_dashboard
from tests.dashboard.scene import Feeder, Scene
from tests.dashboard.server import serve

LATE_S = 6.0


class LateFeeder(Feeder):
    """Ticks stamped ``LATE_S`` before they are sent: a tracker that has fallen behind."""

    def run(self) -> None:
        while not self.stop_event.wait(self.period_s):
            tracks = self.scene.tracks(time.time_ns() - int(LATE_S * 1e9))
            self.scene.state.apply(tracks)
            self.scene.state.apply(self.scene.live_occupancy(tracks))


@pytest.fixture
def late_page(chromium: Chromium) -> Iterator[Page]:
    scene = Scene.build(now_ns=time.time_ns() - int(LATE_S * 1e9))
    app = create_app(scene.site, scene.state, dashboard_dir=DASHBOARD_DIR)
    with LateFeeder(scene), serve(app) as port:
        page = open_dashboard(chromium, f"http://127.0.0.1:{port}/")
        try:
            yield page
        finally:
            page.close()


def test_a_stopped_camera_shows_as_degraded_with_its_reason(page: Page) -> None:
    page.wait_for("!document.getElementById('degraded-banner').hidden", what="the degraded banner")
    assert "camera hall-ne down" in page.evaluate("document.getElementById('degraded-detail').textContent")
    page.wait_for("document.getElementById('system-status').dataset.status === 'degraded'", what="the degraded pill")
    assert "hall-ne" in page.evaluate("document.getElementById('system-status').title")


def test_late_ticks_show_as_degraded_and_are_hatched_in_the_chart(late_page: Page) -> None:
    late_page.wait_for("document.getElementById('degraded-detail').textContent.includes('after capture')",
                       what="the late-ticks reason")
    assert late_page.evaluate("document.getElementById('system-status').dataset.status") == "degraded"
    assert late_page.evaluate("document.getElementById('system-status').textContent") != "all systems ok"
    late_page.wait_for("Number(document.getElementById('chart').dataset.degraded) >= 1", timeout_s=20,
                       what="the degraded period in the chart")


def test_the_map_and_the_occupancy_panel_show_the_same_tick(page: Page, gateway: LiveGateway) -> None:
    page.wait_for("window.bevflow.panelTimeNs", what="the panel from the live ticks")
    same = "window.bevflow.panelTotal === window.bevflow.people && " \
           "document.querySelector('#occupancy-site .big-count').textContent === String(window.bevflow.people)"
    for _ in range(5):  # several ticks: each time, the same count in both
        assert page.evaluate(same) is True
        page.wait_for("document.getElementById('clock').textContent", what="another tick")
