"""``HistoryDatabase`` on both backends: every test runs on SQLite and on PostgreSQL."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow_services.storage import Batch, EventFilter, HistoryDatabase, TrackSummary, ZoneVisit
from tests.services.gateway.feed import S, T0, occupancy, over_capacity, tracks, violation
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

MS = 1_000_000


@pytest.fixture
def db(database_url: str):  # noqa: F811
    with HistoryDatabase.open(database_url) as opened:
        yield opened


def write(db: HistoryDatabase, *messages) -> None:
    batch = Batch()
    for message in messages:
        kind = type(message).__name__
        {"Occupancy": batch.add_occupancy, "Tracks": batch.add_track_sample}.get(kind, batch.add_event)(message)
    db.write(batch)


# --- occupancy -----------------------------------------------------------------------------------
def test_occupancy_keeps_the_highest_count_of_each_second_across_batches(db: HistoryDatabase) -> None:
    for offset_ms, total, gate in [(0, 3, 1), (400, 7, 0), (900, 5, 2), (1000, 2, 2), (2500, 4, 0)]:
        write(db, occupancy(T0 + offset_ms * MS, total, gate=gate))
    samples = db.occupancy()
    assert [(s.time_ns - T0) // S for s in samples] == [0, 1, 2]
    assert [s.total for s in samples] == [7, 2, 4]
    assert [s.zones["gate"] for s in samples] == [2, 2, 0]
    assert {s.step_s for s in samples} == {1}


def test_occupancy_range_is_inclusive(db: HistoryDatabase) -> None:
    write(db, *[occupancy(T0 + k * S, k) for k in range(10)])
    assert [s.total for s in db.occupancy(T0 + 3 * S, T0 + 5 * S)] == [3, 4, 5]


@pytest.mark.parametrize(
    ("step_s", "limit", "offset", "times_s", "totals", "total_steps"),
    [
        (1, 100, 0, [0, 1, 2, 3, 4, 5, 6, 10], [0, 1, 2, 3, 4, 5, 6, 10], 8),
        (5, 100, 0, [0, 5, 10], [4, 6, 10], 3),
        (5, 1, 1, [5], [6], 3),
        (2, 2, 2, [4, 6], [5, 6], 5),
        (60, 10, 5, [], [], 1),
    ],
)
def test_occupancy_steps_are_maxima_paged_oldest_first(
    db: HistoryDatabase, step_s, limit, offset, times_s, totals, total_steps
) -> None:
    write(db, *[occupancy(T0 + k * S, k, gate=k % 2) for k in [*range(7), 10]])
    base = T0 // (step_s * S) * (step_s * S)  # steps are aligned to the epoch
    points, total = db.occupancy_steps(None, None, step_s, limit, offset)
    assert [(p.time_ns - base) // S for p in points] == times_s
    assert [p.total for p in points] == totals
    assert total == total_steps
    assert all(p.step_s == step_s for p in points)


def test_occupancy_steps_respect_the_range(db: HistoryDatabase) -> None:
    write(db, *[occupancy(T0 + k * S, k) for k in range(10)])
    points, total = db.occupancy_steps(T0 + 3 * S, T0 + 7 * S, 5, 10)
    assert [(p.time_ns - T0) // S for p in points] == [0, 5] and [p.total for p in points] == [4, 7]
    assert total == 2


# --- alerts --------------------------------------------------------------------------------------
@pytest.fixture
def alerts(db: HistoryDatabase) -> HistoryDatabase:
    write(db, violation("v1", T0, pair=(1, 2), zone="gate", end_ns=T0 + 5 * S),
          violation("v2", T0 + 10 * S, pair=(2, 3), zone="shop"),
          over_capacity("c1", T0 + 20 * S, zone=None),
          violation("v3", T0 + 30 * S, pair=(4, 5), zone=None, end_ns=T0 + 31 * S))
    return db


@pytest.mark.parametrize(
    ("query", "ids"),
    [
        (EventFilter(), ["v3", "c1", "v2", "v1"]),
        (EventFilter(types=frozenset({"distance_violation"})), ["v3", "v2", "v1"]),
        (EventFilter(types=frozenset()), []),
        (EventFilter(zone="gate"), ["v1"]),
        (EventFilter(track=2), ["v2", "v1"]),
        (EventFilter(active=True), ["c1", "v2"]),
        (EventFilter(active=False), ["v3", "v1"]),
        (EventFilter(since_ns=T0 + 6 * S), ["v3", "c1", "v2"]),  # v1 ended before
        (EventFilter(since_ns=T0 + 4 * S, until_ns=T0 + 15 * S), ["v2", "v1"]),  # overlap
        (EventFilter(until_ns=T0 + 9 * S), ["v1"]),
    ],
)
def test_event_queries(alerts: HistoryDatabase, query: EventFilter, ids: list[str]) -> None:
    events, total = alerts.events(query, limit=100)
    assert [e.id for e in events] == ids
    assert total == len(ids)


def test_event_pages_and_total(alerts: HistoryDatabase) -> None:
    page, total = alerts.events(EventFilter(), limit=2, offset=1)
    assert [e.id for e in page] == ["c1", "v2"] and total == 4
    assert alerts.events(EventFilter(), limit=2, offset=10) == ([], 4)


def test_an_alert_is_one_row_updated_when_it_ends_and_never_reopened(db: HistoryDatabase) -> None:
    write(db, violation("v1", T0))
    write(db, violation("v1", T0))  # a replay of the start
    assert db.event("v1").end_ns is None
    write(db, violation("v1", T0, end_ns=T0 + 4 * S))
    write(db, violation("v1", T0))  # a replayed start, after the end
    write(db, violation("v1", T0, end_ns=T0 + 4 * S))
    events, total = db.events(EventFilter(), limit=10)
    assert total == 1 and events[0].end_ns == T0 + 4 * S
    assert db.row_counts()["events"] == 1 and db.row_counts()["event_tracks"] == 2
    assert db.event("nope") is None


def test_the_whole_body_of_an_alert_comes_back(db: HistoryDatabase) -> None:
    stored = over_capacity("c1", T0, zone="gate", end_ns=T0 + S)
    write(db, stored)
    assert db.event("c1") == stored


def test_a_batch_is_written_whole_or_not_at_all(db: HistoryDatabase) -> None:
    batch = Batch()
    batch.add_event(violation("v1", T0))
    batch.occupancy[(T0, None)] = 3  # type: ignore[index]  # violates NOT NULL: the transaction fails
    with pytest.raises(Exception):  # noqa: B017  (the driver's own integrity error)
        db.write(batch)
    assert db.event("v1") is None
    write(db, violation("v2", T0))  # and the database is still usable
    assert db.event("v2") is not None


# --- tracks --------------------------------------------------------------------------------------
@pytest.fixture
def paths(db: HistoryDatabase) -> HistoryDatabase:
    write(db, tracks(T0, {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (9.0, 0.0)}, zones={1: ["gate"]}))
    write(db, tracks(T0 + S, {1: (0.0, 1.0), 2: (5.0, 0.0), 3: (0.5, 1.0)}, zones={1: ["gate"], 3: ["gate"]}))
    write(db, tracks(T0 + 2 * S, {1: (0.0, 2.0), 4: (0.0, 3.0)}, zones={1: ["shop"], 4: ["shop"]}))
    return db


def test_a_trajectory_is_the_stored_positions_in_the_range(paths: HistoryDatabase) -> None:
    times, xy = paths.trajectory(1)
    assert ((times - T0) // S).tolist() == [0, 1, 2] and xy.tolist() == [[0, 0], [0, 1], [0, 2]]
    times, xy = paths.trajectory(1, T0 + S, T0 + S)
    assert ((times - T0) // S).tolist() == [1] and xy.shape == (1, 2)
    times, xy = paths.trajectory(1, T0 + 5 * S)
    assert len(times) == 0 and xy.shape == (0, 2)
    assert paths.trajectory(99) is None


def test_nearby_positions_are_other_tracks_closer_than_the_limit_at_the_same_time(paths: HistoryDatabase) -> None:
    near = paths.nearby_positions(1, 1.5)
    assert [(i, (t - T0) // S) for i, t, _, _ in near] == [(2, 0), (3, 1), (4, 2)]
    assert paths.nearby_positions(1, 1.5, since_ns=T0 + S, until_ns=T0 + S)[0][:2] == (3, T0 + S)
    assert paths.nearby_positions(1, 0.5) == []


def test_track_summaries_are_newest_first_with_their_zones(paths: HistoryDatabase) -> None:
    summaries, total = paths.track_summaries()
    assert total == 4 and [s.track_id for s in summaries] == [4, 3, 2, 1]
    assert summaries[-1] == TrackSummary(1, T0, T0 + 2 * S, 3, [ZoneVisit("gate", T0, T0 + S), ZoneVisit("shop", T0 + 2 * S, T0 + 2 * S)])
    assert summaries[1] == TrackSummary(3, T0, T0 + S, 2, [ZoneVisit("gate", T0 + S, T0 + S)])


@pytest.mark.parametrize(
    ("kwargs", "ids", "total"),
    [
        ({"zone": "shop"}, [4, 1], 2),
        ({"zone": "gate"}, [3, 1], 2),
        ({"since_ns": T0 + 2 * S}, [4, 1], 2),  # seen at or after
        ({"until_ns": T0}, [3, 2, 1], 3),  # seen at or before
        ({"limit": 2, "offset": 1}, [3, 2], 4),
    ],
)
def test_track_summary_filters(paths: HistoryDatabase, kwargs, ids, total) -> None:
    summaries, count = paths.track_summaries(**kwargs)
    assert [s.track_id for s in summaries] == ids and count == total


def test_sampling_resumes_after_the_newest_stored_position(paths: HistoryDatabase) -> None:
    assert paths.newest_track_time_ns() == T0 + 2 * S


# --- acknowledgements ----------------------------------------------------------------------------
def test_acknowledgements_record_who_and_when(alerts: HistoryDatabase) -> None:
    first = alerts.acknowledge("v2", "ann", T0 + 12 * S, "on my way")
    second = alerts.acknowledge("v2", "bob", T0 + 13 * S)
    alerts.acknowledge("c1", "ann", T0 + 21 * S)
    assert [(a.user, a.time_ns, a.note) for a in alerts.acknowledgements("v2")] == [
        ("ann", T0 + 12 * S, "on my way"), ("bob", T0 + 13 * S, "")]
    assert first.id != second.id and alerts.acknowledgements("v2")[0] == first
    assert len(alerts.acknowledgements()) == 3


@pytest.mark.parametrize(("event_id", "user", "error"), [("nope", "ann", KeyError), ("v1", " ", ValueError)])
def test_acknowledging_needs_a_known_alert_and_a_user(alerts: HistoryDatabase, event_id, user, error) -> None:
    with pytest.raises(error):
        alerts.acknowledge(event_id, user, T0)
    assert alerts.acknowledgements() == []


# --- sharing -------------------------------------------------------------------------------------
def test_a_second_connection_sees_what_the_first_one_wrote(database_url: str) -> None:  # noqa: F811
    with HistoryDatabase.open(database_url) as writer, HistoryDatabase.open(database_url) as reader:
        write(writer, occupancy(T0, 4), violation("v1", T0))
        assert [s.total for s in reader.occupancy()] == [4]
        reader.acknowledge("v1", "ann", T0 + S)
        assert [a.user for a in writer.acknowledgements("v1")] == ["ann"]


def test_positions_keep_their_precision(db: HistoryDatabase) -> None:
    write(db, tracks(T0, {7: (12.345678901, -0.000123456)}))
    _, xy = db.trajectory(7)
    np.testing.assert_array_equal(xy, [[12.345678901, -0.000123456]])


def test_values_beyond_64_bits_match_nothing_instead_of_failing(alerts: HistoryDatabase) -> None:
    huge = 2**70
    assert alerts.events(EventFilter(track=huge), 10) == ([], 0)
    assert [e.id for e in alerts.events(EventFilter(since_ns=huge), 10)[0]] == ["c1", "v2"]  # still active
    assert alerts.events(EventFilter(), 10, offset=huge) == ([], 4)
    assert alerts.trajectory(huge) is None and alerts.nearby_positions(huge, 2.0) == []
    write(alerts, occupancy(T0, 1))
    assert alerts.occupancy_steps(-huge, huge, 60, huge)[1] == 1
    assert alerts.track_summaries(since_ns=-huge, until_ns=huge, offset=huge) == ([], 0)


def test_an_incident_keeps_its_latest_people_until_it_ends(db: HistoryDatabase) -> None:
    from tests.services.gateway.feed import incident

    write(db, incident("i1", T0, people=(1, 2)))
    write(db, incident("i1", T0, people=(1, 2, 3)))  # its people changed while it was open
    assert [e.tracks for e in db.events(EventFilter(), 10)[0]] == [[1, 2, 3]]
    write(db, incident("i1", T0, people=(1, 2, 3, 4), end_ns=T0 + 40 * S))
    write(db, incident("i1", T0, people=(1, 2)))  # a replayed older message never reopens it
    (stored,) = db.events(EventFilter(), 10)[0]
    assert (stored.end_ns, stored.tracks) == (T0 + 40 * S, [1, 2, 3, 4])


def test_the_newest_position_ignores_rows_beyond_a_bound(paths: HistoryDatabase) -> None:
    newest = paths.newest_track_time_ns()
    assert newest is not None
    assert paths.newest_track_time_ns(until_ns=newest - 1) < newest
    assert paths.newest_track_time_ns(until_ns=0) is None


def test_an_open_alert_not_renewed_lapses_and_the_recorder_ends_it(db: HistoryDatabase) -> None:
    """Forged open alerts used to stay active for ever, across gateway restarts too."""
    batch = Batch()
    for name in ("forged", "real"):
        batch.add_event(violation(name, T0))
    db.write(batch, recorded_ns=T0)
    renewal = Batch()
    renewal.renewals = {"real", "unknown"}
    db.write(renewal, recorded_ns=T0 + 50 * S)
    lapsed_before = T0 + 10 * S
    active, total = db.events(EventFilter(active=True, renewed_since_ns=lapsed_before), 10)
    assert [e.id for e in active] == ["real"] and total == 1
    ended, _ = db.events(EventFilter(active=False, renewed_since_ns=lapsed_before), 10)
    assert [(e.id, e.end_ns) for e in ended] == [("forged", T0)]  # shown ended at its last renewal
    assert db.end_lapsed_events(lapsed_before) == 1
    assert db.event("forged").end_ns == T0 and db.event("real").end_ns is None
    assert [e.id for e in db.events(EventFilter(active=True), 10)[0]] == ["real"]
