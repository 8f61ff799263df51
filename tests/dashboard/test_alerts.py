"""The alert feed in a real browser: stored alerts, incidents pushed live over /ws/alerts, acknowledge
(with a note, several at once), clicking an incident to see it on the map, and a feed that holds
still under the pointer."""

from __future__ import annotations

import time

from bevflow.schemas import OverCapacity

from tests.dashboard.cdp import Page
from tests.dashboard.conftest import LiveGateway, alert_node
from tests.dashboard.scene import incident

S = 1_000_000_000


def test_alerts_from_the_gateway_are_listed_newest_first(page: Page) -> None:
    page.wait_for("document.querySelectorAll('#alert-list li').length >= 4", what="the stored alerts")
    ids = page.evaluate("Array.from(document.querySelectorAll('#alert-list li')).map((li) => li.dataset.id)")
    stored = ["inc-1-2", "down-hall-ne", "oc-entrance", "inc-earlier"]  # by start, newest first
    assert [i for i in ids if i in stored] == stored
    assert page.evaluate(f"{alert_node('inc-earlier')}.dataset.active") == "false"
    assert page.evaluate(f"{alert_node('oc-entrance')}.dataset.active") == "true"
    assert "Main entrance" in page.evaluate(f"{alert_node('oc-entrance')}.textContent")


def test_an_incident_pushed_by_the_gateway_appears_live_and_ends_in_place(page: Page, gateway: LiveGateway) -> None:
    page.wait_for(alert_node("inc-earlier"), what="the stored alerts")  # the last to come, over REST
    before = page.evaluate("window.bevflow.attention")
    start = time.time_ns()
    alert = incident("inc-live", start, [3, 4], zone="entrance")
    gateway.scene.state.apply(alert)
    page.wait_for(alert_node("inc-live"), timeout_s=5, what="the pushed incident in the feed")
    text = page.evaluate(f"{alert_node('inc-live')}.textContent")
    assert "Too close" in text and "Main entrance" in text and "#3" in text and "#4" in text and "1.2 m" in text
    assert page.evaluate("document.querySelector('#alert-list li').dataset.id") == "inc-live"  # newest first
    assert page.evaluate("window.bevflow.attention") == before + 1
    assert page.evaluate("document.getElementById('attention').hidden") is False
    assert page.evaluate("document.getElementById('alert-announcer').textContent") == "New alert: Too close, Main entrance"

    gateway.scene.state.apply(alert.model_copy(update={"end_ns": start + 3 * S, "needs_acknowledgement": False}))
    page.wait_for(f"{alert_node('inc-live')}.dataset.active === 'false'", timeout_s=5, what="the incident to end")
    ended = page.evaluate(f"{alert_node('inc-live')}.textContent")
    assert "lasted 3 s" in ended and "no action needed" in ended  # short and over: nothing to acknowledge
    assert page.evaluate(f"{alert_node('inc-live')}.querySelector('.ack-button')") is None
    assert page.evaluate("document.querySelectorAll('#alert-list [data-id=\"inc-live\"]').length") == 1


def test_the_pair_events_behind_incidents_stay_out_of_the_feed(page: Page, gateway: LiveGateway) -> None:
    from bevflow.schemas import DistanceViolation

    page.wait_for(alert_node("inc-earlier"), what="the stored alerts")
    gateway.scene.state.apply(DistanceViolation(id="dv-pair", start_ns=time.time_ns(), tracks=[5, 6], min_distance_m=1.0, limit_m=2.0))
    gateway.scene.state.apply(OverCapacity(id="oc-after-pair", start_ns=time.time_ns(), zone="gate-a", capacity=15, peak=16))
    page.wait_for(alert_node("oc-after-pair"), timeout_s=5, what="the alert sent after the pair event")
    assert page.evaluate(alert_node("dv-pair")) is None


def test_clicking_an_incident_shows_it_and_its_people_on_the_map(page: Page) -> None:
    page.wait_for(alert_node("inc-earlier"), what="the stored alerts")  # the last to come, over REST
    page.click("#alert-list [data-id='inc-1-2'] .alert-type")
    page.wait_for("document.getElementById('map').dataset.focus === 'inc-1-2'", what="the incident on the map")
    page.wait_for("document.getElementById('map').dataset.focusPeople === '1,2'", what="its people marked")
    assert page.evaluate(f"{alert_node('inc-1-2')}.dataset.focused") == "true"
    assert page.evaluate("window.bevflow.focused") == "inc-1-2"
    page.click("#alert-list [data-id='inc-1-2'] .alert-type")  # a second click clears it
    page.wait_for("document.getElementById('map').dataset.focus === ''", what="the map to clear")


def test_acknowledge_marks_the_alert_and_survives_a_reload(page: Page, gateway: LiveGateway) -> None:
    alert = OverCapacity(id="oc-ack", start_ns=time.time_ns(), zone="gate-a", capacity=15, peak=17)
    gateway.scene.state.apply(alert)
    page.wait_for(alert_node("oc-ack"), timeout_s=5, what="the alert to acknowledge")
    page.wait_for(alert_node("inc-earlier"), what="the stored alerts")
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
    page.wait_for(alert_node("inc-earlier"), what="an ended alert")
    visible = "Array.from(document.querySelectorAll('#alert-list li')).filter((li) => !li.hidden).map((li) => li.dataset.id)"
    assert "inc-earlier" in page.evaluate(visible)
    page.click("#show-ended")
    page.wait_for(f"{alert_node('inc-earlier')}.hidden", what="the ended alert to hide")
    shown = page.evaluate(visible)
    assert "inc-1-2" in shown and "oc-entrance" in shown
    assert page.evaluate("Array.from(document.querySelectorAll('#alert-list li:not([hidden])')).every((li) => li.dataset.active === 'true')")


def test_acknowledging_with_a_note_is_one_click(page: Page, gateway: LiveGateway) -> None:
    gateway.scene.state.apply(incident("inc-note", time.time_ns(), [5, 6, 7], zone="gate-a"))
    page.wait_for(alert_node("inc-note"), timeout_s=5, what="the incident to acknowledge")
    page.evaluate(f"{alert_node('inc-note')}.querySelector('.ack-input').value = 'staff on the way'")
    page.click("#alert-list [data-id='inc-note'] .ack-button")
    page.wait_for(f"{alert_node('inc-note')}.dataset.acknowledged === 'true'", what="the acknowledgement")
    assert "staff on the way" in page.evaluate(f"{alert_node('inc-note')}.textContent")
    stored = page.evaluate("fetch('/api/acknowledgements?ids=inc-note').then((r) => r.json())")
    assert [(a["alert_id"], a["note"]) for a in stored] == [("inc-note", "staff on the way")]


def test_acknowledge_all_clears_the_attention_count(page: Page, gateway: LiveGateway) -> None:
    for k in range(2):
        gateway.scene.state.apply(incident(f"inc-bulk-{k}", time.time_ns(), [10 + k, 20 + k]))
    page.wait_for(f"{alert_node('inc-bulk-1')} && window.bevflow.attention >= 2", timeout_s=5, what="the incidents")
    page.click("#ack-all")
    page.wait_for("window.bevflow.attention === 0", what="everything acknowledged")
    assert page.evaluate(f"{alert_node('inc-bulk-0')}.dataset.acknowledged") == "true"
    assert page.evaluate("document.getElementById('ack-all').hidden") is True


def test_the_feed_holds_still_under_the_pointer(page: Page, gateway: LiveGateway) -> None:
    page.wait_for(alert_node("inc-earlier"), what="the stored alerts")
    page.wait_for(alert_node("inc-1-2"), what="the ongoing incident")
    where = page.centre_of("#alert-list [data-id='inc-1-2'] .alert-body")
    page.move_to(where["x"], where["y"])
    top = page.evaluate("document.querySelector('#alert-list li').dataset.id")
    box = "JSON.stringify(document.querySelector('#alert-list [data-id=\"inc-1-2\"]').getBoundingClientRect())"
    before = page.evaluate(box)

    gateway.scene.state.apply(incident("inc-while-hovered", time.time_ns(), [8, 9]))
    page.wait_for("!document.getElementById('alerts-held').hidden", timeout_s=5, what="the new incident to be held back")
    assert page.evaluate(alert_node("inc-while-hovered")) is None
    assert page.evaluate("document.querySelector('#alert-list li').dataset.id") == top
    assert page.evaluate(box) == before  # the item under the pointer did not move
    under_pointer = f"document.elementFromPoint({where['x']:f}, {where['y']:f}).closest('li').dataset.id"
    assert page.evaluate(under_pointer) == "inc-1-2"

    map_centre = page.centre_of("#map")
    page.move_to(map_centre["x"], map_centre["y"])
    page.wait_for("document.querySelector('#alert-list li').dataset.id === 'inc-while-hovered'", timeout_s=5,
                  what="the held incident on top once the pointer left")
    assert page.evaluate("document.getElementById('alerts-held').hidden") is True


def test_notifications_are_off_by_default_and_come_once_per_urgent_alert(page: Page, gateway: LiveGateway) -> None:
    page.wait_for(alert_node("inc-earlier"), what="the stored alerts")
    assert page.evaluate("document.getElementById('notify').checked") is False
    gateway.scene.state.apply(OverCapacity(id="oc-quiet", start_ns=time.time_ns(), zone="gate-a", capacity=15, peak=16))
    page.wait_for(alert_node("oc-quiet"), timeout_s=5, what="an alert while notifications are off")
    assert not page.evaluate("window.bevflow.notified")

    page.click("#notify")
    try:
        start = time.time_ns()
        loud = OverCapacity(id="oc-loud", start_ns=start, zone="gate-a", capacity=15, peak=17)
        gateway.scene.state.apply(loud)
        gateway.scene.state.apply(incident("inc-small", start, [30, 31]))  # low severity: no notification
        gateway.scene.state.apply(loud.model_copy(update={"peak": 19}))  # the same alert again: no second one
        gateway.scene.state.apply(OverCapacity(id="oc-last", start_ns=start, zone="entrance", capacity=8, peak=9))
        page.wait_for(alert_node("oc-last"), timeout_s=5, what="the alerts")
        assert page.evaluate("window.bevflow.notified") == 2  # oc-loud and oc-last
    finally:
        page.click("#notify")  # the setting is per browser: leave it off for the other tests
