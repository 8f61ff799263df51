from __future__ import annotations

import numpy as np
import pytest

from bevflow.analytics.occupancy import OccupancyCounter
from bevflow.analytics.zones import ZoneIndex
from bevflow.schemas import OverCapacity
from bevflow.site import Thresholds, Zone

S = 1_000_000_000
LEFT = Zone(id="left", name="Left wing", polygon=[(0, 0), (10, 0), (10, 10), (0, 10)], capacity=3)
RIGHT = Zone(id="right", polygon=[(10, 0), (20, 0), (20, 10), (10, 10)])


def crowd(count: int, x0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``count`` people spread over a 10 x 10 m square starting at x0."""
    ids = np.arange(count)
    xy = np.stack([x0 + 0.5 + (ids % 19) * 0.5, 0.5 + (ids // 19) * 0.5], axis=1)
    return ids, xy


def capacity_events(counts: list[int], capacity: int, hysteresis: int) -> list[tuple[int, int | None, int, int]]:
    """(tick, end tick or None, start tick, peak) of the site events while counts follow ``counts``."""
    counter = OccupancyCounter("hall", [], Thresholds(site_capacity=capacity, capacity_hysteresis=hysteresis))
    out = []
    for k, n in enumerate(counts):
        _, events = counter.update(k * S, *crowd(n))
        out += [(k, None if e.end_ns is None else e.end_ns // S, e.start_ns // S, e.peak) for e in events]
    return out


@pytest.mark.parametrize(
    ("counts", "capacity", "hysteresis", "expected"),
    [
        pytest.param(
            [49, 50, 51, 50, 49, 51, 50, 49, 51, 48, 49, 50],
            50,
            2,
            [(2, None, 2, 51), (9, 9, 2, 51)],
            id="hovering at the limit: one start, one end",
        ),
        pytest.param(
            [49, 50, 51, 50, 51, 50],
            50,
            0,
            [(2, None, 2, 51), (3, 3, 2, 51), (4, None, 4, 51), (5, 5, 4, 51)],
            id="no hysteresis flaps",
        ),
        pytest.param([10, 50, 50, 10], 50, 2, [], id="at capacity is not over"),
        pytest.param(
            [51, 55, 53, 60, 47],
            50,
            2,
            [(0, None, 0, 51), (4, 4, 0, 60)],
            id="peak is the highest count during the alert",
        ),
        pytest.param([0, 1, 2, 1, 0], 0, 2, [(1, None, 1, 1), (4, 4, 1, 2)], id="capacity 0 ends at 0"),
    ],
)
def test_site_capacity_hysteresis(counts: list[int], capacity: int, hysteresis: int, expected: list) -> None:
    assert capacity_events(counts, capacity, hysteresis) == expected


def test_counts_per_zone_and_site() -> None:
    counter = OccupancyCounter("hall", [LEFT, RIGHT], Thresholds(site_capacity=100))
    ids_left, xy_left = crowd(2, x0=0.0)
    ids_right, xy_right = crowd(5, x0=10.0)
    ids = np.concatenate([ids_left, ids_right + 100, [500]])
    xy = np.concatenate([xy_left, xy_right, [[50.0, 50.0]]])  # one person outside every zone
    occupancy, events = counter.update(7 * S, ids, xy)
    assert (occupancy.site, occupancy.time_ns, occupancy.total, occupancy.capacity) == ("hall", 7 * S, 8, 100)
    assert [(z.id, z.name, z.count, z.capacity) for z in occupancy.zones] == [
        ("left", "Left wing", 2, 3),
        ("right", "", 5, None),
    ]
    assert events == []


def test_zone_alert_names_its_zone() -> None:
    counter = OccupancyCounter("hall", [LEFT, RIGHT], Thresholds(capacity_hysteresis=1))
    _, events = counter.update(1 * S, *crowd(4))
    assert events == [OverCapacity(id=f"capacity-left-{S}", start_ns=S, zone="left", capacity=3, peak=4, raised_ns=S)]
    assert counter.open_alerts == events
    _, events = counter.update(2 * S, *crowd(2))
    assert [(e.id, e.end_ns, e.peak) for e in events] == [(f"capacity-left-{S}", 2 * S, 4)]
    assert counter.open_alerts == []


def test_given_membership_is_used_as_is() -> None:
    counter = OccupancyCounter("hall", [LEFT, RIGHT], Thresholds())
    ids, xy = crowd(3)
    inside = ZoneIndex([LEFT, RIGHT]).contains(xy)
    inside[:, 1] = True  # pretend everyone also stands in "right"
    occupancy, _ = counter.update(0, ids, xy, inside=inside)
    assert [z.count for z in occupancy.zones] == [3, 3]
    with pytest.raises(ValueError, match="shape"):
        counter.update(1, ids, xy, inside=inside[:, :1])


@pytest.mark.parametrize(
    ("counts", "expected"),
    [
        pytest.param([49, 51, 49, 51, 52, 49, 49], [], id="over for less than the minimum: no alert"),
        pytest.param([49, 51, 53, 52, 47], [(3, None, 1, 53), (4, 4, 1, 53)], id="over long enough: starts at the first tick over"),
        pytest.param([51, 52, 49, 51, 51, 51], [(5, None, 3, 51)], id="a dip below restarts the wait"),
    ],
)
def test_over_capacity_waits_for_the_minimum_duration(counts: list[int], expected: list) -> None:
    th = Thresholds(site_capacity=50, capacity_hysteresis=2, capacity_min_duration_s=2.0)
    counter = OccupancyCounter("hall", [], th)
    out = []
    for k, n in enumerate(counts):
        _, events = counter.update(k * S, *crowd(n))
        out += [(k, None if e.end_ns is None else e.end_ns // S, e.start_ns // S, e.peak) for e in events]
    assert out == expected
