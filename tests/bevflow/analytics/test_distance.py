from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from bevflow.analytics.distance import DistanceMonitor
from bevflow.schemas import DistanceViolation, decode_event
from bevflow.site import Thresholds, Zone

S = 1_000_000_000
TICK = 0.1  # seconds between ticks: 10 Hz
Frame = tuple[float, dict[int, tuple[float, float]]]


def frames(duration_s: float, people: Callable[[float], dict[int, tuple[float, float]]]) -> list[Frame]:
    """Ticks at 10 Hz from t = 0 to ``duration_s`` inclusive, with each tick's positions."""
    return [(k * TICK, people(k * TICK)) for k in range(round(duration_s / TICK) + 1)]


def run(
    monitor: DistanceMonitor, ticks: list[Frame], velocities: bool = False
) -> list[tuple[float, DistanceViolation]]:
    """(tick time in seconds, event) for every event published. With ``velocities``, each track's
    velocity is its displacement since the previous tick, zero on its first (as a tracker knows it)."""
    published = []
    previous: dict[int, tuple[float, float]] = {}
    for t, people in ticks:
        ids = list(people)
        xy = np.array([people[i] for i in ids], dtype=float).reshape(-1, 2)
        before = np.array([previous.get(i, people[i]) for i in ids], dtype=float).reshape(-1, 2)
        velocity = (xy - before) / TICK if velocities else None
        published += [(round(t, 6), e) for e in monitor.update(round(t * S), ids, xy, velocity)]
        previous = people
    return published


def summary(published: list[tuple[float, DistanceViolation]]) -> list[tuple]:
    return [
        (t, e.tracks, e.start_ns / S, None if e.end_ns is None else e.end_ns / S, round(e.min_distance_m, 9), e.group)
        for t, e in published
    ]


# --- hand-built scenarios ------------------------------------------------------------------------
def brush_past(t: float) -> dict[int, tuple[float, float]]:
    # Two people walk past each other 1 m apart sideways at 1.2 m/s each: they are closer than
    # 2 m for 2 * sqrt(3) / 2.4 = 1.44 s.
    return {1: (-6 + 1.2 * t, 0.0), 2: (6 - 1.2 * t, 1.0)}


def stand_close(t: float) -> dict[int, tuple[float, float]]:
    # Track 5 stands beside track 9 from 1.0 s to 4.0 s, 1.5 m away, and leans to 1.2 m at 3.5 s.
    beside = 1.0 - 1e-9 <= t <= 4.0 + 1e-9
    x = (1.2 if abs(t - 3.5) < 1e-9 else 1.5) if beside else 10.0
    return {9: (0.0, 0.0), 5: (x, 0.0)}


def couple_then_part(t: float) -> dict[int, tuple[float, float]]:
    # Together (1 m) for 14 s, apart for 3 s, together again; a stranger walks past them.
    apart = 14.0 <= t < 17.0
    return {3: (0.0, 0.0), 4: (6.0 if apart else 1.0, 0.0), 8: (50.0, 0.0)}


def vanish(t: float) -> dict[int, tuple[float, float]]:
    # Track 2 is lost by the tracker at 3.0 s while standing close to track 1.
    people = {1: (0.0, 0.0)}
    if t < 3.0 - 1e-9:
        people[2] = (0.0, 1.0)
    return people


def hover(t: float) -> dict[int, tuple[float, float]]:
    # Close at 1.9 m for 2.5 s, then alternating 2.1 m / 1.95 m every tick until 5 s, then gone far.
    k = round(t / TICK)
    d = 1.9 if t < 2.5 else (2.1 if k % 2 else 1.95) if t < 5.0 else 8.0
    return {1: (0.0, 0.0), 2: (d, 0.0)}


def exactly_at_limit(t: float) -> dict[int, tuple[float, float]]:
    return {1: (0.0, 0.0), 2: (2.0, 0.0)}


def three_in_a_row(t: float) -> dict[int, tuple[float, float]]:
    # 40 - 7 - 12 stand in a line 1.8 m apart: two close pairs, the ends are 3.6 m apart.
    return {40: (0.0, 0.0), 7: (1.8, 0.0), 12: (3.6, 0.0)}


@pytest.mark.parametrize(
    ("scene", "duration_s", "thresholds", "margin", "expected"),
    [
        pytest.param(brush_past, 10, Thresholds(), 0.2, [], id="brush past is no violation"),
        pytest.param(
            stand_close,
            6,
            Thresholds(),
            0.2,
            [(3.0, [5, 9], 1.0, None, 1.5, False), (4.1, [5, 9], 1.0, 4.1, 1.2, False)],
            id="standing close 3 s",
        ),
        pytest.param(
            couple_then_part,
            25,
            Thresholds(group_after_s=10),
            0.2,
            [(2.0, [3, 4], 0.0, None, 1.0, False), (10.0, [3, 4], 0.0, 10.0, 1.0, True)],
            id="a couple becomes a group and stays one",
        ),
        pytest.param(
            lambda t: {3: (0.0, 0.0), 4: (0.8, 0.6)},
            75,
            Thresholds(),
            0.2,
            [(2.0, [3, 4], 0.0, None, 1.0, False), (60.0, [3, 4], 0.0, 60.0, 1.0, True)],
            id="default group_after_s of 60 s",
        ),
        pytest.param(
            couple_then_part,
            25,
            Thresholds(group_after_s=None),
            0.2,
            [
                (2.0, [3, 4], 0.0, None, 1.0, False),
                (14.0, [3, 4], 0.0, 14.0, 1.0, False),
                (19.0, [3, 4], 17.0, None, 1.0, False),
            ],
            id="groups turned off",
        ),
        pytest.param(
            vanish,
            5,
            Thresholds(),
            0.2,
            [(2.0, [1, 2], 0.0, None, 1.0, False), (3.0, [1, 2], 0.0, 3.0, 1.0, False)],
            id="a vanishing track ends the violation",
        ),
        pytest.param(
            hover,
            7,
            Thresholds(),
            0.2,
            [(2.0, [1, 2], 0.0, None, 1.9, False), (5.0, [1, 2], 0.0, 5.0, 1.9, False)],
            id="hysteresis keeps one violation at the limit",
        ),
        pytest.param(
            hover,
            7,
            Thresholds(),
            0.0,
            [(2.0, [1, 2], 0.0, None, 1.9, False), (2.5, [1, 2], 0.0, 2.5, 1.9, False)],
            id="without hysteresis it ends at the first step past the limit",
        ),
        pytest.param(exactly_at_limit, 5, Thresholds(), 0.2, [], id="exactly at the limit is allowed"),
        pytest.param(
            three_in_a_row,
            3,
            Thresholds(),
            0.2,
            [(2.0, [7, 12], 0.0, None, 1.8, False), (2.0, [7, 40], 0.0, None, 1.8, False)],
            id="pairs keyed by smaller id first",
        ),
    ],
)
def test_scenarios(scene: Callable, duration_s: float, thresholds: Thresholds, margin: float, expected: list) -> None:
    published = run(DistanceMonitor(thresholds, release_margin_m=margin), frames(duration_s, scene))
    assert summary(published) == expected


# --- walking together: velocities tell a group on the move from strangers standing close -----------
WALK = 1.2  # m/s


def couple_walking(t: float) -> dict[int, tuple[float, float]]:
    # Side by side, 1 m apart, from the first tick on.
    return {1: (-10 + WALK * t, 0.0), 2: (-10 + WALK * t, 1.0)}


def meet_and_stop(t: float) -> dict[int, tuple[float, float]]:
    # Strangers walk toward each other and stop 1 m apart at 5.5 / 1.2 = 4.58 s; they are closer
    # than 2 m from 5 / 1.2 = 4.17 s on, so from the 4.2 s tick.
    walked = WALK * min(t, 5.5 / WALK)
    return {1: (-6 + walked, 0.0), 2: (6 - walked, 0.0)}


def queue(t: float) -> dict[int, tuple[float, float]]:
    # Three strangers standing in line 1.5 m apart.
    return {1: (0.0, 0.0), 2: (1.5, 0.0), 3: (3.0, 0.0)}


def one_stops_after(walk_s: float) -> Callable[[float], dict[int, tuple[float, float]]]:
    # A couple walks side by side; at walk_s track 1 stops, track 2 drifts on at 0.3 m/s for 2 s
    # (too slow to be walking) and stands 0.6 m ahead of it: still close (1.17 m).
    def scene(t: float) -> dict[int, tuple[float, float]]:
        x = -10 + WALK * min(t, walk_s)
        return {1: (x, 0.0), 2: (x + 0.3 * min(max(t - walk_s, 0.0), 2.0), 1.0)}

    return scene


def overtake(extra_mps: float) -> Callable[[float], dict[int, tuple[float, float]]]:
    # Track 2 starts 3 m behind track 1 and 1 m to its side, and walks extra_mps faster.
    return lambda t: {1: (-10 + WALK * t, 0.0), 2: (-13 + (WALK + extra_mps) * t, 1.0)}


def stand_then_walk_off(t: float) -> dict[int, tuple[float, float]]:
    # Standing 1 m apart for 3 s, then walking off together side by side.
    x = WALK * max(t - 3.0, 0.0)
    return {1: (x, 0.0), 2: (x, 1.0)}


@pytest.mark.parametrize(
    ("scene", "duration_s", "thresholds", "expected", "groups"),
    [
        pytest.param(couple_walking, 20, Thresholds(), [], [[1, 2]], id="a couple walking side by side never alerts"),
        pytest.param(
            couple_walking,
            20,
            Thresholds(group_walk_s=None),
            [(2.0, [1, 2], 0.0, None, 1.0, False)],
            [],
            id="without the walking rule the couple alerts",
        ),
        pytest.param(
            meet_and_stop,
            10,
            Thresholds(),
            [(6.2, [1, 2], 4.2, None, 1.0, False)],
            [],
            id="strangers meeting and stopping 1 m apart alert 2 s later",
        ),
        pytest.param(
            queue,
            5,
            Thresholds(),
            [(2.0, [1, 2], 0.0, None, 1.5, False), (2.0, [2, 3], 0.0, None, 1.5, False)],
            [],
            id="a queue standing 1.5 m apart alerts",
        ),
        pytest.param(
            one_stops_after(4.0),
            10,
            Thresholds(),
            # Last walked together at 4.0 s; the stretch is over once the 1 s grace has passed.
            [(5.1, [1, 2], 0.0, None, 1.0, False)],
            [],
            id="together 4 s then one stops nearby: alert once the walk is over",
        ),
        pytest.param(
            one_stops_after(10.0),
            20,
            Thresholds(),
            [],
            [[1, 2]],
            id="together 10 s then one stops nearby: already a group",
        ),
        pytest.param(brush_past, 10, Thresholds(), [], [], id="crossing pedestrians brushing past"),
        pytest.param(
            overtake(0.35),
            20,
            Thresholds(),
            # Close from 3.7 s; the offset has wandered 0.35 * 4.3 = 1.5 m > walk_drift_m at 8.0 s; closest
            # 1 m (side by side at 8.6 s, 0.01 m ahead); farther than 2.2 m from 14.2 s.
            [(8.0, [1, 2], 3.7, None, round(math.hypot(0.2, 1.0), 9), False),
             (14.2, [1, 2], 3.7, 14.2, round(math.hypot(0.01, 1.0), 9), False)],
            [],
            id="a slow overtaker is alerted once the offset has drifted",
        ),
        pytest.param(
            overtake(1.0),
            8,
            Thresholds(),
            [(3.3, [1, 2], 1.3, None, 1.0, False), (5.0, [1, 2], 1.3, 5.0, 1.0, False)],
            [],
            id="a fast overtaker is alerted after 2 s",
        ),
        pytest.param(
            stand_then_walk_off,
            15,
            Thresholds(),
            # Walking together from the 3.1 s tick: a group 8 s later.
            [(2.0, [1, 2], 0.0, None, 1.0, False), (11.1, [1, 2], 0.0, 11.1, 1.0, True)],
            [[1, 2]],
            id="standing close then walking off together: alerted, then withdrawn",
        ),
    ],
)
def test_walking_together(
    scene: Callable, duration_s: float, thresholds: Thresholds, expected: list, groups: list
) -> None:
    monitor = DistanceMonitor(thresholds)
    assert summary(run(monitor, frames(duration_s, scene), velocities=True)) == expected
    assert monitor.groups.tolist() == groups


def test_walking_pairs_are_held_and_listed() -> None:
    monitor = DistanceMonitor(Thresholds())
    ticks = frames(20, couple_walking)
    run(monitor, ticks[:31], velocities=True)  # 3 s: walking together, no violation
    assert monitor.walking_pairs.tolist() == [[1, 2]]
    assert (monitor.current_pairs.tolist(), monitor.groups.tolist()) == ([], [])
    run(monitor, ticks[31:], velocities=True)  # 20 s: a group, no longer listed as walking
    assert (monitor.walking_pairs.tolist(), monitor.groups.tolist()) == ([], [[1, 2]])


@pytest.mark.parametrize(
    ("velocity", "message"),
    [
        ([[0, 0]], r"\(N, 2\) array of m/s for the 2 tracks"),
        ([[0, 0, 0], [1, 1, 1]], r"got shape \(2, 3\)"),
        ([[0, 0], [np.inf, 0]], "finite"),
    ],
)
def test_bad_velocities_are_refused(velocity: list, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        DistanceMonitor(Thresholds()).update(0, [1, 2], [[0, 0], [1, 1]], velocity)


@pytest.mark.parametrize(
    "option",
    ["release_margin_m", "walk_speed_mps", "walk_tolerance_mps", "walk_grace_s", "velocity_smoothing_s",
     "walk_drift_m"],
)
def test_negative_options_are_refused(option: str) -> None:
    with pytest.raises(ValueError, match=f"{option} must be >= 0"):
        DistanceMonitor(Thresholds(), **{option: -0.1})


def test_start_and_end_share_an_id_and_record_the_closest_approach() -> None:
    zones = [
        Zone(id="west", polygon=[(-5, -5), (0.7, -5), (0.7, 5), (-5, 5)]),
        Zone(id="east", polygon=[(0.7, -5), (5, -5), (5, 5), (0.7, 5)]),
    ]
    published = run(DistanceMonitor(Thresholds(), zones), frames(6, stand_close))
    (started_at, start), (ended_at, end) = published
    assert start.id == end.id == f"distance-5-9-{1 * S}"
    assert start.end_ns is None and end.end_ns == round(4.1 * S)
    assert (start.raised_ns, end.raised_ns) == (round(started_at * S), round(ended_at * S))  # the ticks that raised them
    assert start.limit_m == 2.0
    # Closest approach 1.2 m at x = 1.2, so its midpoint (0.6, 0) lies in "west"; before it, the
    # closest was the first 1.5 m sample, midpoint (0.75, 0), in "east".
    assert (start.position, start.zone) == ((0.75, 0.0), "east")
    assert (end.position, end.zone) == ((0.6, 0.0), "west")
    assert decode_event(end.model_dump_json()) == end


def test_current_pairs_and_groups() -> None:
    monitor = DistanceMonitor(Thresholds(group_after_s=10))
    ticks = frames(25, couple_then_part)
    run(monitor, ticks[:30])  # 2.9 s: the couple is a violation
    assert monitor.current_pairs.tolist() == [[3, 4]]
    assert monitor.groups.tolist() == []
    run(monitor, ticks[30:160])  # 15.9 s: a group, currently apart
    assert monitor.current_pairs.tolist() == []
    assert monitor.groups.tolist() == [[3, 4]]
    monitor.update(round(26 * S), [3], [[0, 0]])  # track 4 is gone: the group is forgotten
    assert monitor.groups.tolist() == []


def test_empty_tick_closes_every_open_violation() -> None:
    monitor = DistanceMonitor(Thresholds())
    run(monitor, frames(3, three_in_a_row))
    ended = monitor.update(round(3.5 * S), [], np.zeros((0, 2)))
    assert sorted((e.tracks, e.end_ns) for e in ended) == [([7, 12], round(3.5 * S)), ([7, 40], round(3.5 * S))]
    assert monitor.current_pairs.shape == (0, 2)


@pytest.mark.parametrize(
    ("ids", "xy", "message"),
    [
        ([1, 2], [[0, 0]], "2 track ids but 1 positions"),
        ([1, 1], [[0, 0], [1, 1]], "repeat"),
        ([1, 2], [[0, 0], [np.nan, 1]], "not finite"),
        ([1, 2], [[0, 0, 0], [1, 1, 1]], r"\(N, 2\)"),
        ([-1, 2], [[0, 0], [1, 1]], "must lie in"),
        ([1.5, 2], [[0, 0], [1, 1]], "integers"),
    ],
)
def test_bad_positions_are_refused(ids: list, xy: list, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        DistanceMonitor(Thresholds()).update(0, ids, xy)


def test_time_must_not_go_backwards() -> None:
    monitor = DistanceMonitor(Thresholds())
    monitor.update(5 * S, [1], [[0, 0]])
    with pytest.raises(ValueError, match="backwards"):
        monitor.update(4 * S, [1], [[0, 0]])


# --- against a plain all-pairs implementation of the same rules ------------------------------------
def reference(ticks: list[Frame], th: Thresholds, margin: float) -> list[tuple]:
    """The documented rules written the obvious way: every pair, every tick, in Python."""
    limit, release = th.social_distance_m, th.social_distance_m + margin
    min_ns, group_ns = round(th.violation_min_duration_s * S), th.group_after_s and round(th.group_after_s * S)
    state: dict[tuple[int, int], dict] = {}
    out = []
    for t_s, people in ticks:
        t = round(t_s * S)
        dist = {(a, b): math.dist(people[a], people[b]) for a in people for b in people if a < b}
        ends, groups, starts = [], [], []
        for key in sorted(state):
            s = state[key]
            d = dist.get(key)
            if d is not None and d <= release:
                s["min"] = min(s["min"], d)
            elif not (s["status"] == "group" and key[0] in people and key[1] in people):
                if s["status"] == "violation":
                    ends.append((key, s["first"], t, s["min"], False))
                del state[key]
        for key in sorted(dist):
            if key not in state and dist[key] < limit:
                state[key] = {"first": t, "status": "close", "min": dist[key]}
        for key in sorted(state):
            s = state[key]
            age = t - s["first"]
            if s["status"] != "group" and group_ns is not None and age >= group_ns:
                if s["status"] == "violation":
                    groups.append((key, s["first"], t, s["min"], True))
                s["status"] = "group"
            elif s["status"] == "close" and age >= min_ns:
                s["status"] = "violation"
                starts.append((key, s["first"], None, s["min"], False))
        out += [(round(t_s, 6), list(k), f, e, round(m, 9), g) for k, f, e, m, g in ends + groups + starts]
    return out


def random_walk(seed: int, people: int = 9, ticks: int = 300) -> list[Frame]:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 6, (people, 2))
    out = []
    for k in range(ticks):
        xy = np.clip(xy + rng.normal(0, 0.15, xy.shape), 0, 6)
        present = rng.random(people) > 0.02  # the tracker drops a track now and then
        out.append((k * TICK, {i: (float(xy[i, 0]), float(xy[i, 1])) for i in range(people) if present[i]}))
    return out


@pytest.mark.parametrize("still", [False, True], ids=["no velocities", "standing still"])
@pytest.mark.parametrize("seed", range(4))
def test_matches_the_all_pairs_reference(seed: int, still: bool) -> None:
    # Velocities of people standing still must change nothing: nobody walks together.
    th = Thresholds(violation_min_duration_s=0.5, group_after_s=3.0)
    ticks = random_walk(seed)
    monitor = DistanceMonitor(th, release_margin_m=0.2)
    published = []
    for t, people in ticks:
        ids, xy = list(people), np.array(list(people.values()), dtype=float).reshape(-1, 2)
        events = monitor.update(round(t * S), ids, xy, np.zeros_like(xy) if still else None)
        published += [(round(t, 6), e) for e in events]
    published = summary(published)
    expected = [(t, k, f / S, None if e is None else e / S, m, g) for t, k, f, e, m, g in reference(ticks, th, 0.2)]
    assert len(expected) > 20  # the walk exercises starts, ends and groups
    assert {g for *_, g in expected} == {False, True}
    assert published == expected
