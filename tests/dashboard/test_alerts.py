"""The alert feed in a real browser: stored alerts, alerts pushed live over /ws/alerts, acknowledge."""

from __future__ import annotations

import time

from bevflow.schemas import DistanceViolation, OverCapacity

from tests.dashboard.cdp import Page
from tests.dashboard.conftest import LiveGateway, alert_node

S = 1_000_000_000


def test_alerts_from_the_gateway_are_listed_newest_first(page: Page) -> None:
    page.wait_for("document.querySelectorAll('#alert-list li').length >= 4", what="the stored alerts")
    ids = page.evaluate("Array.from(document.querySelectorAll('#alert-list li')).map((li) => li.dataset.id)")
    stored = ["dv-1-2", "down-hall-ne", "oc-entrance", "dv-earlier"]  # by start, newest first
    assert [i for i in ids if i in stored] == stored
    assert page.evaluate(f"{alert_node('dv-earlier')}.dataset.active") == "false"
    assert page.evaluate(f"{alert_node('oc-entrance')}.dataset.active") == "true"
    assert "Main entrance" in page.evaluate(f"{alert_node('oc-entrance')}.textContent")


def test_an_alert_pushed_by_the_gateway_appears_live_and_ends_in_place(page: Page, gateway: LiveGateway) -> None:
    page.wait_for(alert_node("dv-earlier"), what="the stored alerts")  # the last to come, over REST
    before = page.evaluate("window.bevflow.attention")
    start = time.time_ns()
    alert = DistanceViolation(id="dv-live", start_ns=start, zone="entrance", tracks=[3, 4], min_distance_m=1.1, limit_m=2.0)
    gateway.scene.state.apply(alert)
    page.wait_for(alert_node("dv-live"), timeout_s=5, what="the pushed alert in the feed")
    text = page.evaluate(f"{alert_node('dv-live')}.textContent")
    assert "Too close" in text and "Main entrance" in text and "#3" in text and "#4" in text and "1.1 m" in text
    assert page.evaluate("document.querySelector('#alert-list li').dataset.id") == "dv-live"  # newest first
    assert page.evaluate("window.bevflow.attention") == before + 1
    assert page.evaluate("document.getElementById('attention').hidden") is False
    assert page.evaluate("document.getElementById('alert-announcer').textContent") == "New alert: Too close, Main entrance"

    gateway.scene.state.apply(alert.model_copy(update={"end_ns": start + 3 * S}))
    page.wait_for(f"{alert_node('dv-live')}.dataset.active === 'false'", timeout_s=5, what="the alert to end")
    assert "lasted 3 s" in page.evaluate(f"{alert_node('dv-live')}.textContent")
    assert page.evaluate("document.querySelectorAll('#alert-list [data-id=\"dv-live\"]').length") == 1


def test_acknowledge_marks_the_alert_and_survives_a_reload(page: Page, gateway: LiveGateway) -> None:
    alert = OverCapacity(id="oc-ack", start_ns=time.time_ns(), zone="gate-a", capacity=15, peak=17)
    gateway.scene.state.apply(alert)
    page.wait_for(alert_node("oc-ack"), timeout_s=5, what="the alert to acknowledge")
    page.wait_for(alert_node("dv-earlier"), what="the stored alerts")
    before = page.evaluate("window.bevflow.attention")
    assert page.evaluate(f"{alert_node('oc-ack')}.dataset.acknowledged") == "false"

    page.click("#alert-list [data-id='oc-ack'] .ack-button")
    page.wait_for(f"{alert_node('oc-ack')}.dataset.acknowledged === 'true'", what="the acknowledgement")
    assert page.evaluate(f"{alert_node('oc-ack')}.querySelector('.ack-button')") is None
    assert "acknowledged" in page.evaluate(f"{alert_node('oc-ack')}.textContent")
    assert page.evaluate("window.bevflow.attention") == before - 1
    stored = page.evaluate("fetch('/api/acknowledgements?ids=oc-ack').then((r) => r.json())")
    assert [(a["alert_id"], a["user"]) for a in stored] == [("oc-ack", "local")]  # kept by the gateway

    page.reload()
    page.wait_for(f"window.bevflow && window.bevflow.ready && {alert_node('oc-ack')}", timeout_s=10, what="the reloaded feed")
    assert page.evaluate(f"{alert_node('oc-ack')}.dataset.acknowledged") == "true"


def test_show_ended_hides_and_shows_the_ended_alerts(page: Page) -> None:
    page.wait_for(alert_node("dv-earlier"), what="an ended alert")
    visible = "Array.from(document.querySelectorAll('#alert-list li')).filter((li) => !li.hidden).map((li) => li.dataset.id)"
    assert "dv-earlier" in page.evaluate(visible)
    page.click("#show-ended")
    page.wait_for(f"{alert_node('dv-earlier')}.hidden", what="the ended alert to hide")
    shown = page.evaluate(visible)
    assert "dv-1-2" in shown and "oc-entrance" in shown
    assert page.evaluate("Array.from(document.querySelectorAll('#alert-list li:not([hidden])')).every((li) => li.dataset.active === 'true')")
