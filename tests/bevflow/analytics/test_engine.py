from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest

from bevflow.analytics.engine import SiteAnalytics
from bevflow.schemas import DistanceViolation, OverCapacity, Tracks, TrackState
from bevflow.site import Site

S = 1_000_000_000
TICK = S // 10

SITE = Site.model_validate(
    {
        "site": "hall",
        "cameras": [
            {
                "id": "c0",
                "image_size": [1024, 1024],
                "intrinsics": {"fx": 300, "fy": 300, "cx": 512, "cy": 512},
                "pose": {"position": [5.0, 5.0, 4.0]},
            }
        ],
        "zones": [
            {"id": "bar", "polygon": [[0, 0], [4, 0], [4, 4], [0, 4]], "capacity": 2, "crowded_level": 1},
            {"id": "stage", "polygon": [[6, 0], [10, 0], [10, 4], [6, 4]]},
        ],
        "thresholds": {"site_capacity": 10, "capacity_hysteresis": 1, "group_after_s": 30},
    }
)


def test_one_call_per_tick_gives_every_analytic() -> None:
    analytics = SiteAnalytics(SITE, crowded_gap_s=0, crowded_min_duration_s=0)
    ids = np.array([11, 12, 13, 20])
    xy = np.array([[1.0, 1.0], [2.0, 1.0], [3.5, 3.5], [8.0, 2.0]])  # three in the bar, one on the stage
    ticks = [analytics.update(k * TICK, ids, xy) for k in range(21)]  # 0 .. 2 s

    first = ticks[0]
    assert (first.occupancy.total, [z.count for z in first.occupancy.zones]) == (4, [3, 1])
    assert [(type(e), e.zone, e.start_ns) for e in first.events] == [(OverCapacity, "bar", 0)]
    assert first.zones_by_track == {11: ["bar"], 12: ["bar"], 13: ["bar"], 20: ["stage"]}
    assert first.zones_by_row == [["bar"], ["bar"], ["bar"], ["stage"]]  # in the order of the ids given
    assert first.violations.shape == (0, 2)

    # 11-12 (1 m) and 12-13 (2.9 m: no) -> one violation at 2 s; 11-13 is 3.5 m apart.
    last = ticks[-1]
    violations = [e for e in last.events if isinstance(e, DistanceViolation)]
    assert [(v.tracks, v.start_ns, v.zone, v.min_distance_m) for v in violations] == [([11, 12], 0, "bar", 1.0)]
    assert last.violations.tolist() == [[11, 12]]
    assert analytics.crowded_now[0].zone == "bar" and analytics.crowded_now[0].peak == 3

    # Everyone leaves the bar: the violation ends (track gone), capacity and crowding end too.
    end = analytics.update(21 * TICK, [20], [[8.0, 2.0]])
    assert sorted((type(e).__name__, e.end_ns) for e in end.events) == [
        ("DistanceViolation", 21 * TICK),
        ("OverCapacity", 21 * TICK),
    ]
    after = analytics.update(22 * TICK, [20], [[8.0, 2.0]])
    assert [(i.zone, i.start_ns, i.end_ns, i.peak) for i in after.intervals] == [("bar", 0, 21 * TICK, 3)]


def test_tick_feeds_the_wire_messages() -> None:
    analytics = SiteAnalytics(SITE)
    tick = analytics.update(5 * S, [1, 2], [[1.0, 1.0], [1.5, 1.0]])
    zones = tick.zones_by_track
    message = Tracks(
        site=SITE.site,
        time_ns=5 * S,
        tracks=[TrackState(id=1, xy=(1.0, 1.0), zones=zones[1]), TrackState(id=2, xy=(1.5, 1.0), zones=zones[2])],
        violations=[tuple(p) for p in tick.violations.tolist()],
    )
    assert Tracks.model_validate_json(message.model_dump_json()) == message
    assert tick.occupancy.site == "hall" and tick.occupancy.capacity == 10


def test_trajectories_and_contacts_through_the_facade() -> None:
    analytics = SiteAnalytics(SITE, history_period_s=1.0)
    for k in range(31):  # 0 .. 3 s at 10 Hz
        analytics.update(k * TICK, [1, 2], [[0.0, 0.0], [3.0 - k * 0.05, 0.0]])
    assert analytics.trajectory(2).times_ns.tolist() == [0, S, 2 * S, 3 * S]
    # Track 2 is at 3.0, 2.5, 2.0, 1.5 m at the sampled ticks: closer than 2 m only at 3 s.
    assert [(c.track, c.first_ns, c.min_distance_m) for c in analytics.contacts(1)] == [(2, 3 * S, 1.5)]
    assert [c.track for c in analytics.contacts(1, limit_m=2.6)] == [2]
    off = SiteAnalytics(SITE, history_max_tracks=0)
    off.update(0, [1], [[0, 0]])
    with pytest.raises(KeyError, match="turned off"):
        off.trajectory(1)


@pytest.mark.parametrize(
    ("with_velocity", "violations"),
    [(False, [[1, 2]]), (True, [])],
    ids=["positions alone: a violation", "velocities: a couple walking together"],
)
def test_velocities_reach_the_distance_monitor(with_velocity: bool, violations: list) -> None:
    analytics = SiteAnalytics(SITE)
    velocity = np.array([[1.2, 0.0], [1.2, 0.0]])
    for k in range(31):  # 0 .. 3 s, side by side 1 m apart along the bar and past it
        xy = np.array([[0.5 + 0.12 * k, 1.0], [0.5 + 0.12 * k, 2.0]])
        tick = analytics.update(k * TICK, [1, 2], xy, velocity if with_velocity else None)
    assert tick.violations.tolist() == violations


def test_site_crowding_is_tracked_at_80_percent_of_capacity() -> None:
    analytics = SiteAnalytics(SITE, crowded_gap_s=0, crowded_min_duration_s=0)
    ids = np.arange(9)
    analytics.update(0, ids, np.column_stack([ids * 1.0 + 20, np.zeros(9)]))  # 9 people outside every zone
    assert [(i.zone, i.level, i.peak) for i in analytics.crowded_now] == [(None, 8, 9)]


@pytest.mark.parametrize(
    "module",
    ["zones", "distance", "occupancy", "intervals", "trajectories", "contacts"],
)
def test_docstring_examples_run(module: str) -> None:
    result = doctest.testmod(importlib.import_module(f"bevflow.analytics.{module}"))
    assert result.attempted > 0 and result.failed == 0
