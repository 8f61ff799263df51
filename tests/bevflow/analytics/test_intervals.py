from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bevflow.analytics.intervals import CrowdedIntervalTracker, crowded_intervals
from bevflow.schemas import CrowdedInterval


def spans(intervals: list[CrowdedInterval]) -> list[tuple[int, int | None, int, int]]:
    return [(i.start_ns, i.end_ns, i.peak, i.peak_ns) for i in intervals]


@pytest.mark.parametrize(
    ("times", "counts", "level", "gap", "shortest", "expected"),
    [
        pytest.param([0, 1, 2, 3], [1, 2, 3, 4], 4, 0, 0, [], id="never above the level"),
        pytest.param([0, 1, 2, 3, 4, 5], [1, 5, 6, 2, 1, 1], 4, 0, 0, [(1, 3, 6, 2)], id="one interval"),
        pytest.param([0, 1, 2, 3], [1, 1, 5, 6], 4, 0, 0, [(2, 3, 6, 3)], id="crowded at the end"),
        pytest.param([0, 1, 2], [5, 1, 1], 4, 0, 0, [(0, 1, 5, 0)], id="crowded at the start"),
        pytest.param([0, 1, 2, 3, 4], [1, 5, 2, 6, 1], 4, 1, 0, [(1, 4, 6, 3)], id="short dip merged"),
        pytest.param(
            [0, 1, 2, 3, 4], [1, 5, 2, 6, 1], 4, 0, 0, [(1, 2, 5, 1), (3, 4, 6, 3)], id="no merging without a gap"
        ),
        pytest.param([0, 1, 2, 3, 4], [5, 1, 1, 5, 1], 4, 1, 0, [(0, 1, 5, 0), (3, 4, 5, 3)], id="long dip splits"),
        pytest.param([0, 1, 2, 3, 4, 5, 6], [1, 5, 1, 6, 6, 6, 1], 4, 0, 2, [(3, 6, 6, 3)], id="too short dropped"),
        pytest.param(
            [0, 1, 2, 3, 4, 5, 6], [1, 5, 1, 6, 6, 6, 1], 4, 1, 4, [(1, 6, 6, 3)], id="merged before the length test"
        ),
        pytest.param([0, 1, 2, 3, 4], [4, 7, 5, 7, 4], 4, 0, 0, [(1, 4, 7, 1)], id="peak tie keeps the first"),
        pytest.param(
            [0, 10, 11, 40, 45, 100],
            [0, 30, 31, 0, 35, 0],
            20,
            35,
            0,
            [(10, 100, 35, 45)],
            id="irregular sampling",
        ),
        pytest.param([5], [9], 4, 0, 0, [(5, 5, 9, 5)], id="one sample"),
        pytest.param([], [], 4, 0, 0, [], id="empty"),
    ],
)
def test_crowded_intervals(times: list, counts: list, level: int, gap: int, shortest: int, expected: list) -> None:
    found = crowded_intervals(times, counts, level, min_gap_ns=gap, min_duration_ns=shortest, zone="z")
    assert spans(found) == expected
    assert all(i.zone == "z" and i.level == level for i in found)


@pytest.mark.parametrize(
    ("times", "counts", "level", "message"),
    [
        ([0, 1], [1], 4, "2 times but 1 counts"),
        ([0, 2, 1], [1, 1, 1], 4, "decrease"),
        ([0, 1], [1, 1], -1, "level"),
    ],
)
def test_bad_series_are_refused(times: list, counts: list, level: int, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        crowded_intervals(times, counts, level)


def live(times: list[int], counts: list[int], level: int, gap: int, shortest: int) -> list[CrowdedInterval]:
    tracker = CrowdedIntervalTracker(level, min_gap_ns=gap, min_duration_ns=shortest)
    found = [i for t, c in zip(times, counts, strict=True) if (i := tracker.update(t, c)) is not None]
    last = tracker.flush()
    return found + ([last] if last is not None else [])


@settings(max_examples=200, deadline=None)
@given(
    steps=st.lists(st.tuples(st.integers(1, 5), st.integers(0, 8)), min_size=1, max_size=40),
    level=st.integers(0, 6),
    gap=st.integers(0, 6),
    shortest=st.integers(0, 8),
)
def test_tracker_finds_what_the_batch_function_finds(steps: list, level: int, gap: int, shortest: int) -> None:
    times, t = [], 0
    for dt, _ in steps:
        t += dt
        times.append(t)
    counts = [c for _, c in steps]
    assert spans(live(times, counts, level, gap, shortest)) == spans(
        crowded_intervals(times, counts, level, min_gap_ns=gap, min_duration_ns=shortest)
    )


def test_tracker_reports_an_interval_once_the_dip_outlasts_the_gap() -> None:
    tracker = CrowdedIntervalTracker(level=4, min_gap_ns=2, zone="hall")
    assert tracker.current is None
    reported = [tracker.update(t, c) for t, c in enumerate([1, 5, 7, 2, 2, 2, 2])]
    # The dip starts at t=3; at t=5 it has lasted 2 (could still merge), at t=6 it is over.
    assert reported[:6] == [None] * 6
    assert spans([reported[6]]) == [(1, 3, 7, 2)]
    assert tracker.current is None


def test_tracker_shows_the_interval_in_progress() -> None:
    tracker = CrowdedIntervalTracker(level=4, zone="hall")
    for t, c in enumerate([1, 5, 9, 6]):
        tracker.update(t, c)
    assert tracker.current == CrowdedInterval(zone="hall", level=4, start_ns=1, end_ns=None, peak=9, peak_ns=2)
    with pytest.raises(ValueError, match="backwards"):
        tracker.update(2, 5)
