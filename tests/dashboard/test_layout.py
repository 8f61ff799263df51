"""The dashboard at the screen sizes of a control room and a laptop: nothing spills sideways, the top
bar stays one row, and at 1280×720 and up the alerts and camera health are on screen without
scrolling."""

from __future__ import annotations

import json

import pytest

from tests.dashboard.cdp import Page

MEASURE = """JSON.stringify({
  scrollWidth: document.documentElement.scrollWidth, scrollHeight: document.documentElement.scrollHeight,
  topbar: document.querySelector('.topbar').getBoundingClientRect().height,
  alertsTop: document.getElementById('alerts').getBoundingClientRect().top,
  camerasBottom: document.getElementById('cameras').getBoundingClientRect().bottom,
  healthBottom: document.querySelector('.health-panel').getBoundingClientRect().bottom,
  spilling: Array.from(document.querySelectorAll('.panel, .alert, .topbar'))
    .filter((n) => n.scrollWidth > n.clientWidth + 1).map((n) => n.className),
})"""


@pytest.mark.parametrize(("width", "height", "fits"), [(1600, 1000, True), (1280, 720, True), (1024, 768, False)])
def test_the_layout_fits_the_screen(page: Page, width: int, height: int, fits: bool) -> None:
    page.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
    page.wait_for(f"innerWidth === {width} && document.querySelectorAll('#cameras li').length === 4", what="the resized page")
    page.wait_for("document.querySelectorAll('#alert-list li').length >= 4", what="the alerts")
    page.evaluate("new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    m = json.loads(page.evaluate(MEASURE))
    assert m["scrollWidth"] <= width, m  # no sideways scrolling
    assert m["spilling"] == [], m
    assert m["topbar"] < 60, m  # one row
    assert m["alertsTop"] < height / 2, m  # the feed starts in the upper half
    if fits:  # the page itself does not scroll; camera health is on screen
        assert m["scrollHeight"] <= height and m["healthBottom"] <= height, m
        assert m["camerasBottom"] <= m["healthBottom"], m
