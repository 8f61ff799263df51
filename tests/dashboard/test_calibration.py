"""The calibration page in headless Chromium: click points in the camera's frame, type their floor
positions, preview the pose with each point's error, save, and find the pose in the site file.

The site file says the camera hangs at (5, 4, 4) looking straight down; the clicked pixels are
where floor points appear through its true pose (``calibration_site``), so a save must move it."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from bevflow.schemas import CalibrationDrift
from bevflow.site import load_site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.site_file import site_file_of
from tests.dashboard.cdp import Chromium, Page
from tests.dashboard.conftest import DASHBOARD_DIR
from tests.dashboard.server import serve
from tests.services.gateway.calibration_site import FLOOR_POINTS, SITE_YAML, TRUE_POSITION, site, true_pixels


@dataclass
class CalibrationGateway:
    url: str
    site_file: Path
    state: GatewayState


@pytest.fixture(scope="module")
def calibration_gateway(tmp_path_factory: pytest.TempPathFactory) -> Iterator[CalibrationGateway]:
    site_file = tmp_path_factory.mktemp("site") / "hall.yaml"
    site_file.write_text(SITE_YAML, encoding="utf-8")
    state = GatewayState(site())
    app = create_app(state.site, state, dashboard_dir=DASHBOARD_DIR)
    app.state.site_file = site_file_of(site_file)
    with serve(app) as port:
        yield CalibrationGateway(f"http://127.0.0.1:{port}/", site_file, state)


@pytest.fixture
def calibration_page(chromium: Chromium, calibration_gateway: CalibrationGateway) -> Iterator[Page]:
    calibration_gateway.site_file.write_text(SITE_YAML, encoding="utf-8")
    page = chromium.new_page()
    page.goto(calibration_gateway.url + "calibration.html")
    page.wait_for("window.calibration && window.calibration.ready", timeout_s=15, what="the camera's frame")
    try:
        yield page
    finally:
        page.close()


def click_image_pixel(page: Page, u: float, v: float) -> None:
    """Click where full-image pixel (u, v) is shown, however the image is scaled on screen."""
    box = page.evaluate(
        """(() => { const img = document.getElementById('frame'); const r = img.getBoundingClientRect();
                    return {left: r.left, top: r.top, factor: r.width / img.naturalWidth}; })()"""
    )
    page.click_at(box["left"] + u * box["factor"], box["top"] + v * box["factor"])


def type_into(page: Page, selector: str, text: str) -> None:
    page.click(selector)
    page.call("Input.insertText", {"text": text})
    page.press("Enter", text="\r")


def test_click_points_preview_and_save_changes_the_site_file(calibration_page: Page, calibration_gateway: CalibrationGateway) -> None:
    page = calibration_page
    assert page.evaluate("window.calibration.imageSize") == [800, 800]
    assert page.evaluate("window.calibration.frameSource") == "rendered"  # no camera sends frames here
    assert page.evaluate("document.getElementById('camera-select').value") == "gate"
    for k, ((u, v), (x, y)) in enumerate(zip(true_pixels(), FLOOR_POINTS, strict=True)):
        click_image_pixel(page, u, v)
        page.wait_for(f"document.querySelectorAll('#points-body tr').length === {k + 1}", what=f"row {k + 1}")
        row = f"#points-body tr[data-index='{k}']"
        clicked = page.evaluate(f"[...document.querySelectorAll(\"{row} td\")].slice(1, 3).map(td => Number(td.textContent))")
        one_screen_pixel = 1.0 / page.evaluate("(() => { const i = document.getElementById('frame'); return i.getBoundingClientRect().width / i.naturalWidth; })()")
        assert np.allclose(clicked, [u, v], atol=one_screen_pixel + 0.05)  # the pixel of the full image, not of the screen
        type_into(page, f"{row} input[name='x']", f"{x:g}")
        type_into(page, f"{row} input[name='y']", f"{y:g}")
    page.wait_for("window.calibration.solution && window.calibration.solution.points.length === 8", what="the preview")
    errors = page.evaluate("[...document.querySelectorAll('#points-body td.error-px')].map(td => td.textContent)")
    assert len(errors) == 8 and all(float(e) < 3.0 for e in errors), errors  # each point's error, shown
    assert "RMS reprojection error" in page.evaluate("document.getElementById('solution').textContent")
    assert calibration_gateway.site_file.read_text(encoding="utf-8") == SITE_YAML  # a preview saves nothing

    page.click("#save")
    page.wait_for("window.calibration.saved", what="the save")
    text = calibration_gateway.site_file.read_text(encoding="utf-8")
    assert text != SITE_YAML and "# over the main door" in text
    saved = load_site(calibration_gateway.site_file)
    gate = next(c for c in saved.cameras if c.id == "gate")
    assert gate.pose is None and gate.extrinsics is not None
    assert np.allclose(saved.camera("gate").center, TRUE_POSITION, atol=0.1)
    status = page.evaluate("document.getElementById('status').textContent")
    assert "saved into" in status and "restart the projector and tracker" in status
    assert page.errors() == []


def test_too_few_points_cannot_be_previewed_and_a_bad_point_is_flagged(calibration_page: Page) -> None:
    page = calibration_page
    pixels = true_pixels()
    for k in range(3):
        click_image_pixel(page, *pixels[k])
        type_into(page, f"#points-body tr[data-index='{k}'] input[name='x']", f"{FLOOR_POINTS[k][0]:g}")
        type_into(page, f"#points-body tr[data-index='{k}'] input[name='y']", f"{FLOOR_POINTS[k][1]:g}")
    assert page.evaluate("document.getElementById('preview').disabled") is True
    assert "1 more point" in page.evaluate("document.getElementById('status').textContent")
    for k in range(3, 6):  # the fourth point's floor position typed 1 m off
        click_image_pixel(page, *pixels[k])
        x, y = FLOOR_POINTS[k]
        type_into(page, f"#points-body tr[data-index='{k}'] input[name='x']", f"{x:g}")
        type_into(page, f"#points-body tr[data-index='{k}'] input[name='y']", f"{y + (1.0 if k == 3 else 0.0):g}")
    page.wait_for("window.calibration.solution && window.calibration.solution.points.length === 6", what="the preview")
    assert page.evaluate("window.calibration.solution.accepted") is False
    assert page.evaluate("document.getElementById('save').disabled") is True
    flagged = page.evaluate("[...document.querySelectorAll('#points-body td.error-m.error-bad')].length")
    assert flagged >= 1
    assert "pose refused" in page.evaluate("document.getElementById('solution').textContent")


def test_a_floor_point_can_be_clicked_on_the_plan(calibration_page: Page) -> None:
    page = calibration_page
    click_image_pixel(page, *true_pixels()[0])
    page.wait_for("document.querySelectorAll('#points-body tr').length === 1")
    # Where the plan draws (3, 2): the plan's own mapping is checked through the typed value.
    box = page.evaluate(
        """(() => { const c = document.getElementById('plan'); const r = c.getBoundingClientRect();
                    return {left: r.left, top: r.top, width: r.width, height: r.height}; })()"""
    )
    floor = (0.0, 0.0, 16.0, 8.0)
    pad = 24
    scale = min((box["width"] - 2 * pad) / (floor[2] - floor[0]), (box["height"] - 2 * pad) / (floor[3] - floor[1]))
    left = (box["width"] - (floor[2] - floor[0]) * scale) / 2
    top = (box["height"] - (floor[3] - floor[1]) * scale) / 2
    page.click_at(box["left"] + left + 3.0 * scale, box["top"] + top + (8.0 - 2.0) * scale)
    values = page.evaluate("['x', 'y'].map(n => Number(document.querySelector(`#points-body tr[data-index='0'] input[name=${n}]`).value))")
    assert np.allclose(values, [3.0, 2.0], atol=0.051)


def test_arrow_keys_move_the_selected_point_by_a_pixel(calibration_page: Page) -> None:
    page = calibration_page
    click_image_pixel(page, 300.0, 300.0)
    page.wait_for("document.querySelectorAll('#points-body tr').length === 1")
    before = page.evaluate("window.calibration.points()[0].pixel")
    page.click("#points-title")  # away from the inputs, where arrows would edit the number
    page.press("ArrowRight")
    page.press("ArrowDown")
    page.press("ArrowDown")
    after = page.evaluate("window.calibration.points()[0].pixel")
    assert np.allclose(np.subtract(after, before), [1.0, 2.0])
    cells = page.evaluate("[...document.querySelectorAll(\"#points-body tr td\")].slice(1, 3).map(td => Number(td.textContent))")
    assert np.allclose(cells, after, atol=0.051)


def test_drift_is_shown_per_camera(calibration_page: Page, calibration_gateway: CalibrationGateway) -> None:
    event = CalibrationDrift(id="drift-shop", start_ns=1_700_000_000_000_000_000, camera="shop", shift_m=0.18, reference_camera="gate")
    calibration_gateway.state.apply(event)
    try:
        calibration_page.reload()
        calibration_page.wait_for("document.querySelector('#drift-list [data-camera=\"shop\"][data-state=\"moved\"]')", what="the drift badge")
        text = calibration_page.evaluate("document.querySelector('#drift-list [data-camera=\"shop\"]').textContent")
        assert "moved 0.18 m" in text
        assert calibration_page.evaluate("document.querySelector('#drift-list [data-camera=\"gate\"]').dataset.state") == "ok"
    finally:
        calibration_gateway.state.apply(event.model_copy(update={"end_ns": event.start_ns + 1}))


def test_the_dashboard_links_to_the_page() -> None:
    index = (DASHBOARD_DIR / "index.html").read_text(encoding="utf-8")
    assert 'href="calibration.html"' in index
