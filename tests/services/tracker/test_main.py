from __future__ import annotations

import pytest

from bevflow.schemas import CameraHealthEvent, OverCapacity

from bevflow_services.tracker.main import CameraWatch, OpenAlertBook

S = 1_000_000_000


def test_a_silent_camera_goes_down_once_and_comes_back_up() -> None:
    watch = CameraWatch(["a", "b"], timeout_ns=5 * S, now_ns=0)
    watch.seen("a", 4 * S)
    assert watch.check(5 * S) == []
    (down,) = watch.check(6 * S)  # b silent since 0
    assert (down.type, down.camera, down.start_ns, down.end_ns, down.raised_ns) == ("camera_down", "b", 0, None, 6 * S)
    assert watch.check(7 * S) == []  # reported once, not every tick
    watch.seen("b", 8 * S)
    ended, up = watch.check(8 * S)
    assert (ended.id, ended.type, ended.end_ns, ended.raised_ns) == (down.id, "camera_down", 8 * S, 8 * S)
    assert up.type == "camera_up" and up.camera == "b" and up.raised_ns == 8 * S


def test_a_camera_that_keeps_dropping_out_is_one_alert_until_it_reports_steadily() -> None:
    watch = CameraWatch(["a"], timeout_ns=5 * S, now_ns=0, up_after_ns=10 * S)
    (down,) = watch.check(6 * S)
    events = []
    for t in (8, 9, 16, 17, 18, 22, 26, 28, 30, 32, 34):  # back at 8, silent 9..16 (> 5 s), steady from 16
        watch.seen("a", t * S)
        events += watch.check(t * S)
    ended, up = events
    assert (ended.id, ended.end_ns) == (down.id, 16 * S)  # one outage, ended when the steady stretch began
    assert up.type == "camera_up" and up.start_ns == 16 * S
    assert watch.check(35 * S) == []


@pytest.mark.parametrize(
    ("first_report_s", "down_at_s", "reason"),
    [
        pytest.param(30, 31, "no results since the tracker started 30 s ago", id="a grace for the first result"),
        pytest.param(0, 6, "no results since the tracker started 5 s ago", id="no grace: the silence timeout"),
        pytest.param(2, 6, "no results since the tracker started 5 s ago", id="never shorter than the timeout"),
    ],
)
def test_a_camera_that_never_reported_is_down_after_its_first_report_grace(first_report_s, down_at_s, reason) -> None:
    """At a site's start the detectors load their models before the first results: a camera not
    heard from since the tracker started is down only after ``first_report_ns``; one that has
    reported and falls silent still goes down after the timeout."""
    watch = CameraWatch(["late", "lost"], timeout_ns=5 * S, now_ns=0, first_report_ns=first_report_s * S)
    watch.seen("lost", 1 * S)
    events = [e for t in range(1, 40) for e in watch.check(t * S)]
    by_camera = {e.camera: e for e in events if e.type == "camera_down"}
    assert (by_camera["late"].raised_ns, by_camera["late"].reason) == (down_at_s * S, reason)
    assert (by_camera["lost"].raised_ns, by_camera["lost"].reason) == (7 * S, "no results for 5 s")


def test_the_tracker_renews_the_alerts_it_has_open_every_few_seconds() -> None:
    book = OpenAlertBook("hall", renew_every_s=15.0)
    S = 1_000_000_000
    book.observe(OverCapacity(id="c1", start_ns=0, capacity=3, peak=4))
    book.observe(CameraHealthEvent(id="down", type="camera_down", camera="a", start_ns=0))
    first = book.renewal(10 * S)
    assert first is not None and (first.site, first.time_ns, first.ids) == ("hall", 10 * S, ["c1", "down"])
    assert book.renewal(24 * S) is None  # not due yet
    book.observe(OverCapacity(id="c1", start_ns=0, end_ns=20 * S, capacity=3, peak=4))
    book.observe(CameraHealthEvent(id="up", type="camera_up", camera="a", start_ns=21 * S, end_ns=21 * S))
    due = book.renewal(25 * S)
    assert due is not None and due.ids == ["down"]
