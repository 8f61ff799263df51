from __future__ import annotations

import pytest

from bevflow_services.gateway.history import EventQuery, InMemoryHistory
from tests.services.gateway.feed import S, T0, occupancy, over_capacity, tracks, violation

MS = 1_000_000


def test_occupancy_keeps_the_highest_count_of_each_second() -> None:
    history = InMemoryHistory()
    for offset_ms, total, gate in [(0, 3, 1), (400, 7, 0), (900, 5, 2), (1000, 2, 2), (2500, 4, 0)]:
        history.add_occupancy(occupancy(T0 + offset_ms * MS, total, gate=gate))
    samples = history.occupancy()
    assert [(s.time_ns - T0) // S for s in samples] == [0, 1, 2]
    assert [s.total for s in samples] == [7, 2, 4]
    assert [s.zones["gate"] for s in samples] == [2, 2, 0]


def test_occupancy_forgets_seconds_older_than_the_retention_and_ignores_late_ones() -> None:
    history = InMemoryHistory(retention_s=10)
    for k in range(30):
        history.add_occupancy(occupancy(T0 + k * S, k))
    history.add_occupancy(occupancy(T0 + 5 * S, 99))  # late, for a second already closed
    samples = history.occupancy()
    assert [s.total for s in samples] == list(range(19, 30))


def test_occupancy_range_is_inclusive() -> None:
    history = InMemoryHistory()
    for k in range(10):
        history.add_occupancy(occupancy(T0 + k * S, k))
    assert [s.total for s in history.occupancy(T0 + 3 * S, T0 + 5 * S)] == [3, 4, 5]


def _events() -> InMemoryHistory:
    history = InMemoryHistory()
    history.add_event(violation("v1", T0, pair=(1, 2), zone="gate", end_ns=T0 + 5 * S))
    history.add_event(violation("v2", T0 + 10 * S, pair=(2, 3), zone="shop"))
    history.add_event(over_capacity("c1", T0 + 20 * S, zone=None))
    history.add_event(violation("v3", T0 + 30 * S, pair=(4, 5), zone=None, end_ns=T0 + 31 * S))
    return history


@pytest.mark.parametrize(
    ("query", "ids"),
    [
        (EventQuery(), ["v3", "c1", "v2", "v1"]),
        (EventQuery(types=frozenset({"distance_violation"})), ["v3", "v2", "v1"]),
        (EventQuery(zone="gate"), ["v1"]),
        (EventQuery(track=2), ["v2", "v1"]),
        (EventQuery(active=True), ["c1", "v2"]),
        (EventQuery(active=False), ["v3", "v1"]),
        (EventQuery(since_ns=T0 + 6 * S), ["v3", "c1", "v2"]),  # v1 ended before
        (EventQuery(since_ns=T0 + 4 * S, until_ns=T0 + 15 * S), ["v2", "v1"]),  # overlap
        (EventQuery(until_ns=T0 + 9 * S), ["v1"]),
    ],
)
def test_event_queries(query: EventQuery, ids: list[str]) -> None:
    events, total = _events().events(query, limit=100)
    assert [e.id for e in events] == ids
    assert total == len(ids)


def test_event_pages_and_total() -> None:
    history = _events()
    page, total = history.events(EventQuery(), limit=2, offset=1)
    assert [e.id for e in page] == ["c1", "v2"] and total == 4
    assert history.events(EventQuery(), limit=2, offset=10) == ([], 4)


def test_the_oldest_events_go_first_when_over_the_cap() -> None:
    history = InMemoryHistory(max_events=3)
    for k in range(5):
        history.add_event(violation(f"v{k}", T0 + k * S))
    assert [e.id for e in history.events(EventQuery(), 10)[0]] == ["v4", "v3", "v2"]


def test_trajectories_and_contacts_come_from_the_track_history() -> None:
    history = InMemoryHistory(track_period_s=1.0)
    for k in range(5):  # track 2 walks towards track 1 and passes 1 m from it at k = 3
        history.add_tracks(tracks(T0 + k * S, {1: (0.0, 0.0), 2: (4.0 - k, 0.0), 3: (50.0, 50.0)}))
    path = history.trajectory(2, since_ns=T0 + S, until_ns=T0 + 3 * S)
    assert path is not None and path.xy[:, 0].tolist() == [3.0, 2.0, 1.0]
    found = history.contacts(1, limit_m=2.0)
    assert found is not None and [(c.track, c.first_ns, c.min_distance_m) for c in found] == [(2, T0 + 3 * S, 0.0)]
    assert history.trajectory(99) is None and history.contacts(99, 2.0) is None


def test_retention_must_be_positive() -> None:
    with pytest.raises(ValueError, match="retention_s"):
        InMemoryHistory(retention_s=0)
