from __future__ import annotations

import pytest

from bevflow.live.assembler import TickAssembler

MS = 1_000_000


def make(cameras=("a", "b"), period_ms=100, wait_ms=150, future_ms=2000) -> TickAssembler[str]:
    return TickAssembler(list(cameras), period_ns=period_ms * MS, max_wait_ns=wait_ms * MS, max_future_ns=future_ms * MS)


def primed(cameras=("a", "b")) -> TickAssembler[str]:
    """An assembler that has heard from every camera (in an earlier slot, already released)."""
    a = make(cameras)
    for c in cameras:
        a.push(c, 900 * MS, "hello", now_ns=1000 * MS)
    a.pop_ready(now_ns=1000 * MS)
    return a


def test_slot_released_as_soon_as_every_camera_reported() -> None:
    a = primed()
    assert a.push("a", 1010 * MS, "a1", now_ns=1020 * MS) == "accepted"
    assert a.pop_ready(now_ns=1020 * MS) == []
    a.push("b", 1050 * MS, "b1", now_ns=1060 * MS)
    (tick,) = a.pop_ready(now_ns=1060 * MS)
    assert tick.start_ns == 1000 * MS and tick.items == {"a": "a1", "b": "b1"}
    assert tick.time_ns == 1050 * MS


def test_dead_camera_delays_by_at_most_max_wait() -> None:
    a = primed()
    a.push("a", 1010 * MS, "a1", now_ns=1010 * MS)
    assert a.pop_ready(now_ns=1249 * MS) == []  # slot ends at 1100, +150 ms wait
    (tick,) = a.pop_ready(now_ns=1250 * MS)
    assert tick.items == {"a": "a1"}


@pytest.mark.parametrize(
    ("camera", "capture_ms", "now_ms", "expected"),
    [
        ("zz", 1300, 1300, "unknown_camera"),
        ("a", 9000, 1300, "future"),  # more than 2 s ahead of the clock
        ("a", 1050, 1300, "late"),  # its slot was already released
        ("a", 1300, 1300, "accepted"),
    ],
)
def test_rejections_are_classified_and_counted(camera: str, capture_ms: int, now_ms: int, expected: str) -> None:
    a = make()
    a.push("a", 1010 * MS, "x", now_ns=1010 * MS)
    a.push("b", 1020 * MS, "y", now_ns=1020 * MS)
    a.pop_ready(now_ns=1020 * MS)
    assert a.push(camera, capture_ms * MS, "z", now_ns=now_ms * MS) == expected
    assert a.counts[expected] >= 1


def test_ticks_leave_in_time_order_even_when_a_newer_slot_completes_first() -> None:
    a = primed()
    a.push("a", 1010 * MS, "old-a", now_ns=1010 * MS)  # b never reports for slot 1000
    a.push("a", 1110 * MS, "new-a", now_ns=1110 * MS)
    a.push("b", 1120 * MS, "new-b", now_ns=1120 * MS)
    ticks = a.pop_ready(now_ns=1120 * MS)
    assert [t.start_ns for t in ticks] == [1000 * MS, 1100 * MS]
    assert ticks[0].items == {"a": "old-a"}


@pytest.mark.parametrize(
    ("b_capture_ms", "released"),
    [
        (1120, [1000]),  # b skipped slot 1000 and moved on: nothing more is coming for it
        (1099, [1000]),  # b reported into slot 1000 itself
        (990, []),  # b is behind: slot 1000 waits for it
    ],
)
def test_a_camera_that_reported_a_later_capture_is_not_waited_for(b_capture_ms: int, released: list[int]) -> None:
    a = make(cameras=("a", "b", "c"))
    for camera in ("a", "b", "c"):
        a.push(camera, 900 * MS, "hello", now_ns=950 * MS)
    a.pop_ready(now_ns=950 * MS)  # slot 900 complete: every camera is live
    a.push("a", 1010 * MS, "a1", now_ns=1020 * MS)
    a.push("c", 1030 * MS, "c1", now_ns=1040 * MS)
    a.push("b", b_capture_ms * MS, "b", now_ns=1130 * MS)
    assert [t.start_ns // MS for t in a.pop_ready(now_ns=1130 * MS)] == released  # long before 1100 + 150 ms


def test_newest_message_of_a_camera_wins_within_a_slot() -> None:
    a = make(cameras=("a",))
    a.push("a", 1050 * MS, "second", now_ns=1050 * MS)
    a.push("a", 1010 * MS, "first-but-late", now_ns=1051 * MS)
    (tick,) = a.pop_ready(now_ns=1051 * MS)
    assert tick.items == {"a": "second"}


def test_flush_returns_pending_slots_in_order() -> None:
    a = make()
    a.push("a", 1210 * MS, "c", now_ns=0)
    a.push("a", 1010 * MS, "a", now_ns=0)
    assert [t.items["a"] for t in a.flush()] == ["a", "c"]
    assert a.pending == 0
    assert a.push("a", 1150 * MS, "late", now_ns=2000 * MS) == "late"


def test_invalid_configuration_is_refused() -> None:
    with pytest.raises(ValueError, match="period_ns"):
        TickAssembler(["a"], period_ns=0)


def test_a_camera_never_heard_from_is_not_waited_for() -> None:
    a = make()
    a.push("a", 1010 * MS, "a1", now_ns=1010 * MS)
    assert [t.items for t in a.pop_ready(now_ns=1010 * MS)] == [{"a": "a1"}]


def test_a_camera_silent_for_longer_than_stale_is_no_longer_waited_for() -> None:
    a = TickAssembler(["a", "b"], period_ns=100 * MS, max_wait_ns=150 * MS, stale_ns=1000 * MS)
    a.push("b", 1010 * MS, "b-last-words", now_ns=1010 * MS)
    a.push("a", 1020 * MS, "a1", now_ns=1020 * MS)
    a.pop_ready(now_ns=1020 * MS)
    a.push("a", 3010 * MS, "a2", now_ns=3010 * MS)  # b has been silent for 2 s
    (tick,) = a.pop_ready(now_ns=3010 * MS)
    assert tick.items == {"a": "a2"}


def test_a_camera_whose_results_arrive_late_is_waited_for_again() -> None:
    # b's results take 300 ms to arrive, more than max_wait: its first ones miss their ticks, but
    # they show b is alive, so later ticks wait for it instead of dropping everything it sends.
    a = TickAssembler(["a", "b"], period_ns=100 * MS, max_wait_ns=400 * MS, stale_ns=1000 * MS)
    a.push("a", 1000 * MS, "a1", now_ns=1000 * MS)
    a.pop_ready(now_ns=1000 * MS)  # b never heard: the first tick leaves with a alone
    assert a.push("b", 1000 * MS, "b1", now_ns=1300 * MS) == "late"
    a.push("a", 1400 * MS, "a2", now_ns=1400 * MS)
    assert a.pop_ready(now_ns=1400 * MS) == []  # now b is waited for
    assert a.push("b", 1400 * MS, "b2", now_ns=1700 * MS) == "accepted"
    (tick,) = a.pop_ready(now_ns=1700 * MS)
    assert tick.items == {"a": "a2", "b": "b2"}
