"""The dashboard in a real browser (headless Chromium) against a live gateway: the page, the map,
occupancy, health, and a screenshot.

The gateway serves a hall with 44 people (``scene.py``): the entrance over capacity, the food court
crowded, two pairs too close together, one camera down, and alerts. Each test opens a fresh tab.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow_services.gateway import GatewayState, create_app

from tests.dashboard.cdp import Chromium, Page
from tests.dashboard.conftest import DASHBOARD_DIR, LiveGateway
from tests.dashboard.scene import UP_CAMERAS, VIOLATIONS, hall
from tests.dashboard.server import serve


def test_page_loads_live_without_console_errors(page: Page, gateway: LiveGateway) -> None:
    page.wait_for("document.querySelectorAll('#zone-bars li').length === 3", what="the zone bars")
    assert page.evaluate("document.getElementById('site-name').textContent") == "hall"
    assert page.evaluate("document.querySelector('#connection-banner').hidden") is True
    assert page.evaluate("document.title").endswith("hall · bevflow")
    assert page.errors() == []


def test_a_gateway_without_data_yet_shows_an_empty_site_without_errors(chromium: Chromium) -> None:
    site = hall()
    with serve(create_app(site, GatewayState(site), dashboard_dir=DASHBOARD_DIR)) as port:
        page = chromium.new_page()
        try:
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for("window.bevflow && window.bevflow.ready", what="the dashboard")
            page.wait_for("document.getElementById('system-status').dataset.status === 'no_data'", what="the no-data status")
            page.wait_for("document.querySelectorAll('#cameras li').length === 4", what="the camera badges")
            page.wait_for("document.querySelector('#occupancy-site .big-count')?.textContent === '0'", what="a count of 0")
            assert page.evaluate("window.bevflow.people") == 0
            assert page.evaluate("document.getElementById('alerts-empty').hidden") is False
            assert page.evaluate("document.querySelector('#cameras li').dataset.state") == "unknown"
            assert page.errors() == []
        finally:
            page.close()


def test_map_shows_every_person_and_the_pairs_too_close(page: Page, gateway: LiveGateway) -> None:
    people = len(gateway.scene.ids)
    assert page.evaluate("window.bevflow.people") == people
    assert page.evaluate("window.bevflow.violations") == len(VIOLATIONS)
    assert page.evaluate("document.getElementById('map').dataset.people") == str(people)
    # The drawing itself: a person far from the others is a light dot; one of a violating pair is red.
    # Far from the cameras too: a camera's icon and name are drawn over the people.
    xy = gateway.scene.crowd.positions(time.time())
    site = gateway.scene.site
    cameras = np.array([site.camera(c).center[:2] for c in site.camera_ids])
    gaps = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy)) * 1e9
    clear = np.minimum(gaps.min(axis=1), np.linalg.norm(xy[:, None] - cameras[None], axis=2).min(axis=1))
    loner = int(np.argmax(clear)) + 1
    # Two animation frames first: a layout change (a panel growing) moves the canvas at once but
    # redraws it on the next frame, and until then the dots lie off their places.
    colours = page.evaluate(
        f"""(async () => {{
            await new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)));
            const canvas = document.getElementById('map');
            const box = canvas.getBoundingClientRect();
            const ratio = canvas.width / box.width;
            const at = (id) => {{
                const p = window.bevflow.screenOf(id);
                return Array.from(canvas.getContext('2d').getImageData((p.x - box.left) * ratio, (p.y - box.top) * ratio, 1, 1).data);
            }};
            return {{loner: at({loner}), violating: at(1)}};
        }})()"""
    )
    red, green, blue, _ = colours["violating"]
    assert red > 200 and green < 120 and blue < 120, colours
    assert min(colours["loner"][:3]) > 180, colours  # near-white
    assert page.evaluate("document.querySelectorAll('#people-list .person-button').length") == people


def test_map_follows_the_window_size(page: Page) -> None:
    size = "(() => { const c = document.getElementById('map'); return [c.width, c.height, c.clientWidth, c.clientHeight]; })()"
    page.wait_for(f"{size}[0] === {size}[2] && {size}[0] > 0", what="the first frame")
    wide = page.evaluate(size)
    page.call("Emulation.setDeviceMetricsOverride", {"width": 1100, "height": 800, "deviceScaleFactor": 1, "mobile": False})
    page.wait_for(f"{size}[2] < {wide[2]} && {size}[0] === {size}[2] && {size}[1] === {size}[3]", what="the map to redraw smaller")
    where = page.evaluate("window.bevflow.screenOf(3)")
    assert where is not None and 0 < where["x"] < 1100 and 0 < where["y"] < 800


@pytest.mark.parametrize(
    ("zone", "level", "count"),
    [("entrance", "over_capacity", "10 / 8"), ("food-court", "crowded", "16 / 20"), ("gate-a", "normal", "3 / 15")],
)
def test_zone_bars_show_count_against_capacity(page: Page, zone: str, level: str, count: str) -> None:
    row = f"document.querySelector('#zone-bars [data-zone={json.dumps(zone)}]')"
    page.wait_for(row, what=f"the {zone} bar")
    assert page.evaluate(f"{row}.dataset.level") == level
    assert page.evaluate(f"{row}.querySelector('.zone-count').textContent") == count


def test_health_shows_services_and_cameras(page: Page) -> None:
    page.wait_for("document.querySelectorAll('#cameras li').length === 4", what="the camera badges")
    cameras = page.evaluate("Object.fromEntries(Array.from(document.querySelectorAll('#cameras li')).map((li) => [li.dataset.camera, li.dataset.state]))")
    assert cameras == {**{c: "up" for c in UP_CAMERAS}, "hall-ne": "down"}
    services = page.evaluate("Array.from(document.querySelectorAll('#services li')).map((li) => li.textContent)")
    assert {"gatewayup", "ingest ×3up", "trackerup", "detectorup", "projectorup"} <= set(services)
    page.wait_for("document.getElementById('system-status').dataset.status === 'degraded'", what="the degraded status")


def test_screenshot_is_a_rendered_dashboard(page: Page, tmp_path: Path) -> None:
    page.wait_for("document.querySelectorAll('#cameras li').length === 4", what="the health panel")
    time.sleep(0.5)  # a few ticks, so trails have grown
    png = page.screenshot()
    (tmp_path / "dashboard.png").write_bytes(png)
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (1000, 1600, 3)
    assert image.std() > 10
    coarse = image.astype(np.int32) // 16
    colours = np.unique((coarse[..., 0] << 8) | (coarse[..., 1] << 4) | coarse[..., 2])
    assert len(colours) > 50  # far from a uniform colour

    page.click("#people-list [data-track='1']")
    page.wait_for("document.getElementById('person-panel').dataset.loaded === 'true'", what="the person panel")
    (tmp_path / "dashboard-person.png").write_bytes(page.screenshot())


def test_each_zone_has_a_sparkline_of_its_last_minutes(page: Page) -> None:
    page.wait_for("document.querySelectorAll('#zone-bars .sparkline polyline').length === 3", timeout_s=20, what="the sparklines")
    points = page.evaluate("document.querySelector('#zone-bars [data-zone=\"entrance\"] .sparkline polyline').getAttribute('points')")
    assert len(points.split()) > 10  # ten minutes at one point per 10 s
    assert page.errors() == []
