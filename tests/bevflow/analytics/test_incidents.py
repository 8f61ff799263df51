"""Distance incidents: pair violations grouped, debounced and closed with hysteresis."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.analytics.incidents import IncidentTracker, connected_groups, severity
from bevflow.schemas import DistanceIncident
from bevflow.site import Thresholds, Zone

S = 1_000_000_000
# These tests script who is in violation when; arrival together (``bevflow.analytics.companions``)
# has tests of its own, here it is off: every scripted pair is two strangers.
NO_COMPANIONS = {"incident_companion_window_s": 0.0}
# Where each track stands (metres): 1-4 and 5-6 around (0, 0), 7-8 far away at (30, 0).
SPOT = {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (1.5, 0.8), 4: (0.5, 1.2), 5: (0.2, 0.3), 6: (1.1, 0.2), 7: (30.0, 0.0), 8: (31.0, 0.0)}


def run(script: list[tuple[int, list[tuple[int, int]]]], **thresholds: float) -> list[DistanceIncident]:
    """Feed (second, pairs in violation) ticks, one a second with nothing in between, then ten
    quiet seconds; every event published, in order."""
    th = Thresholds(**{"incident_min_duration_s": 2.0, "incident_quiet_s": 2.0, "incident_ack_min_s": 5.0, **NO_COMPANIONS,
                       **thresholds})
    tracker = IncidentTracker(th)
    events: list[DistanceIncident] = []
    by_second = dict(script)
    last = max(by_second) + 10
    for second in range(last + 1):
        pairs = by_second.get(second, [])
        events += tracker.update(second * S, np.array(pairs, dtype=np.int64).reshape(-1, 2), list(SPOT), list(SPOT.values()))
    return events


def summary(events: list[DistanceIncident]) -> list[tuple[str, int, int | None, int]]:
    """(which incident: a, b, ... in order of appearance, start second, end second, people)."""
    names: dict[str, str] = {}
    out = []
    for e in events:
        name = names.setdefault(e.id, "abcdefgh"[len(names)])
        out.append((name, e.start_ns // S, None if e.end_ns is None else e.end_ns // S, e.people))
    return out


def seconds(a: int, b: int, pairs: list[tuple[int, int]]) -> list[tuple[int, list[tuple[int, int]]]]:
    return [(t, pairs) for t in range(a, b + 1)]


@pytest.mark.parametrize(
    ("script", "expected"),
    [
        pytest.param(seconds(0, 1, [(1, 2)]), [], id="a contact shorter than the minimum is no incident"),
        pytest.param(seconds(0, 4, [(1, 2)]), [("a", 0, None, 2), ("a", 0, 4, 2)], id="a pair opens after 2 s, closes after the quiet"),
        pytest.param(seconds(0, 4, [(1, 2), (2, 3), (3, 4)]), [("a", 0, None, 4), ("a", 0, 4, 4)], id="a group of four is one incident"),
        pytest.param(
            seconds(0, 3, [(1, 2), (2, 3)]) + seconds(4, 6, [(1, 2)]) + seconds(7, 9, [(1, 2), (2, 4)]),
            [("a", 0, None, 3), ("a", 0, None, 3), ("a", 0, None, 3), ("a", 0, 9, 3)],
            id="people leave and join: still one incident, republished as they change"),
        pytest.param(seconds(0, 3, [(1, 2)]) + seconds(5, 7, [(1, 2)]), [("a", 0, None, 2), ("a", 0, 7, 2)],
                     id="a gap within the quiet time continues it"),
        pytest.param(seconds(0, 3, [(1, 2)]) + seconds(7, 9, [(1, 2)]),
                     [("a", 0, None, 2), ("a", 0, 3, 2), ("b", 7, None, 2), ("b", 7, 9, 2)],
                     id="a gap longer than the quiet time starts a new one"),
        pytest.param(seconds(0, 3, [(1, 2)]) + seconds(4, 6, [(5, 6)]), [("a", 0, None, 2), ("a", 0, None, 2), ("a", 0, 6, 2)],
                     id="new ids at the same place (tracker churn) continue it"),
        pytest.param(seconds(0, 3, [(1, 2), (7, 8)]),
                     [("a", 0, None, 2), ("b", 0, None, 2), ("a", 0, 3, 2), ("b", 0, 3, 2)],
                     id="two groups apart are two incidents"),
        pytest.param(seconds(0, 3, [(1, 2)]) + seconds(2, 3, [(1, 2), (3, 4)]) + seconds(4, 5, [(1, 2), (2, 3), (3, 4)]),
                     [("a", 0, None, 2), ("a", 0, None, 4), ("a", 0, 5, 4)],
                     id="a group that grows into a nearby pair before it opens takes it in"),
    ],
)
def test_incidents_follow_groups(script: list[tuple[int, list[tuple[int, int]]]], expected: list[tuple]) -> None:
    assert summary(run(script)) == expected


def test_two_open_incidents_that_meet_merge_into_the_older() -> None:
    far = {**SPOT, 3: (6.0, 0.0), 4: (7.0, 0.0)}
    th = Thresholds(incident_min_duration_s=2.0, incident_quiet_s=2.0, **NO_COMPANIONS)
    tracker = IncidentTracker(th)
    events = []
    for t in range(6):
        pairs = [(1, 2)] + ([(3, 4)] if t >= 1 else [])
        events += tracker.update(t * S, np.array(pairs), list(far), list(far.values()))
    events += tracker.update(6 * S, np.array([(1, 2), (2, 3), (3, 4)]), list(far), list(far.values()))
    older, younger = sorted({e.id for e in events}, key=lambda i: min(e.start_ns for e in events if e.id == i))
    at_merge = [e for e in events if e.raised_ns == 6 * S]
    assert [(e.id, e.end_ns) for e in at_merge if e.id == younger] == [(younger, 6 * S)]
    assert [(e.id, e.end_ns, e.people) for e in at_merge if e.id == older] == [(older, None, 4)]
    assert [e.id for e in tracker.open_incidents] == [older]


@pytest.mark.parametrize(
    ("pairs", "last_second", "needs"),
    [
        pytest.param([(1, 2)], 3, False, id="short, two people, ended: nothing to acknowledge"),
        pytest.param([(1, 2)], 6, True, id="longer than incident_ack_min_s"),
        pytest.param([(1, 2), (2, 3)], 3, True, id="short but three people (medium)"),
    ],
)
def test_ended_short_incidents_need_no_acknowledgement(pairs: list[tuple[int, int]], last_second: int, needs: bool) -> None:
    events = run(seconds(0, last_second, pairs))
    assert all(e.needs_acknowledgement for e in events if e.end_ns is None)
    assert [e.needs_acknowledgement for e in events if e.end_ns is not None] == [needs]


@pytest.mark.parametrize(
    ("people", "duration_s", "expected"),
    [(2, 0.0, "low"), (2, 59.9, "low"), (3, 0.0, "medium"), (2, 60.0, "medium"), (4, 299.0, "medium"),
     (5, 0.0, "high"), (2, 300.0, "high")],
)
def test_severity(people: int, duration_s: float, expected: str) -> None:
    assert severity(people, duration_s) == expected


@pytest.mark.parametrize(
    ("pairs", "expected"),
    [([], []), ([(1, 2)], [[1, 2]]), ([(3, 1), (2, 3), (9, 8)], [[1, 2, 3], [8, 9]]), ([(5, 6), (1, 2), (2, 6)], [[1, 2, 5, 6]])],
)
def test_connected_groups(pairs: list[tuple[int, int]], expected: list[list[int]]) -> None:
    assert connected_groups(np.array(pairs, dtype=np.int64).reshape(-1, 2)) == expected


def test_an_incident_carries_where_who_and_how_close() -> None:
    zone = Zone(id="gate", polygon=[(-1, -1), (3, -1), (3, 3), (-1, 3)])
    tracker = IncidentTracker(Thresholds(incident_min_duration_s=0.0, **NO_COMPANIONS), [zone])
    (event,) = tracker.update(0, np.array([(1, 2), (2, 3)]), list(SPOT), list(SPOT.values()))
    assert event.zone == "gate" and event.tracks == [1, 2, 3] and event.current == [1, 2, 3] and event.people == 3
    assert event.min_distance_m == pytest.approx(np.hypot(0.5, 0.8))
    assert event.position == pytest.approx((2.5 / 3, 0.8 / 3))
    assert event.severity == "medium" and event.limit_m == 2.0


def test_people_who_arrive_together_open_no_incident_and_strangers_still_do() -> None:
    """1 and 2 are close from their first tick on (they came in together); 3 and 4 are seen
    from the start but meet only at 5 s."""
    th = Thresholds(incident_min_duration_s=2.0, incident_quiet_s=2.0, incident_companion_window_s=2.0)
    tracker = IncidentTracker(th)
    far = {**SPOT, 3: (6.0, 0.0), 4: (7.0, 0.0)}
    events = []
    for t in range(12):
        pairs = [(1, 2)] + ([(3, 4)] if t >= 5 else [])
        events += tracker.update(t * S, np.array(pairs), [1, 2, 3, 4], [far[i] for i in (1, 2, 3, 4)])
    assert {tuple(e.tracks) for e in events} == {(3, 4)}
