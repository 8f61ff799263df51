from __future__ import annotations

from bevflow_services.tracker.main import CameraWatch

S = 1_000_000_000


def test_a_silent_camera_goes_down_once_and_comes_back_up() -> None:
    watch = CameraWatch(["a", "b"], timeout_ns=5 * S, now_ns=0)
    watch.seen("a", 4 * S)
    assert watch.check(5 * S) == []
    (down,) = watch.check(6 * S)  # b silent since 0
    assert (down.type, down.camera, down.start_ns, down.end_ns) == ("camera_down", "b", 0, None)
    assert watch.check(7 * S) == []  # reported once, not every tick
    watch.seen("b", 8 * S)
    ended, up = watch.check(8 * S)
    assert (ended.id, ended.type, ended.end_ns) == (down.id, "camera_down", 8 * S)
    assert up.type == "camera_up" and up.camera == "b"


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
