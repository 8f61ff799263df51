"""Downsampling and retention, on both backends."""

from __future__ import annotations

import pytest

from bevflow_services.storage import Batch, EventFilter, HistoryDatabase, RetentionPolicy
from tests.services.gateway.feed import S, T0, occupancy, tracks, violation
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

MIN = 60 * S
B = (T0 // MIN + 1) * MIN  # capture times start on a minute here


@pytest.fixture
def db(database_url: str):  # noqa: F811
    with HistoryDatabase.open(database_url) as opened:
        yield opened


def write_occupancy(db: HistoryDatabase, seconds: range, total=lambda k: k % 10) -> None:
    batch = Batch()
    for k in seconds:
        batch.add_occupancy(occupancy(B + k * S, total(k), gate=1))
    db.write(batch)


def test_old_seconds_become_minutes_with_their_maximum_and_mean(db: HistoryDatabase) -> None:
    write_occupancy(db, range(0, 180))  # three minutes (B is on a minute), total k % 10
    policy = RetentionPolicy(fine_s=100, coarse_step_s=60)
    result = db.apply_retention(policy, now_ns=B + 230 * S)  # fine from B + 130 s: minutes 0 and 1 roll up
    assert result.done and result.rolled_up_rows == 120 * 3
    points = db.occupancy()
    assert [(p.time_ns - B) // S for p in points[:3]] == [0, 60, 120]
    assert [p.step_s for p in points[:3]] == [60, 60, 1]
    assert [p.total for p in points[:2]] == [9, 9] and points[0].zones == {"gate": 1, "shop": 0}
    assert len(points) == 2 + 60
    (mean,), = db.backend.query("SELECT mean_people FROM occupancy_coarse WHERE zone = '' AND time_ns = ?", [B])
    assert mean == pytest.approx(4.5)


def test_coarse_steps_read_like_any_other_occupancy(db: HistoryDatabase) -> None:
    assert db.newest_occupancy_ns() is None
    write_occupancy(db, range(0, 120), total=lambda k: k)
    db.apply_retention(RetentionPolicy(fine_s=30), now_ns=B + 150 * S)
    assert db.newest_occupancy_ns() == B + 60 * S  # only coarse rows are left
    points, total = db.occupancy_steps(None, None, 60, 10)
    assert [(p.time_ns - B) // S for p in points] == [0, 60] and [p.total for p in points] == [59, 119]
    assert total == 2


def test_a_minute_rolled_up_twice_merges_its_maximum_and_mean(db: HistoryDatabase) -> None:
    write_occupancy(db, range(0, 30), total=lambda k: 2)
    db.apply_retention(RetentionPolicy(fine_s=1), now_ns=B + 200 * S)
    write_occupancy(db, range(30, 60), total=lambda k: 6)  # late data for the same minute
    db.apply_retention(RetentionPolicy(fine_s=1), now_ns=B + 200 * S)
    rows = db.backend.query("SELECT max_people, mean_people, seconds FROM occupancy_coarse WHERE zone = ''")
    assert rows == [(6, pytest.approx(4.0), 60)]


def test_a_backlog_is_worked_off_a_slice_per_call(db: HistoryDatabase) -> None:
    write_occupancy(db, range(0, 600))  # ten minutes, all beyond the fine window
    policy = RetentionPolicy(fine_s=1)
    calls = []
    while True:
        result = db.apply_retention(policy, now_ns=B + 3600 * S, max_span_s=150)
        calls.append(result.rolled_up_rows // 3)
        if result.done:
            break
    assert calls == [120, 120, 120, 120, 120]  # 150 s slices, cut on minute edges
    assert db.row_counts()["occupancy"] == 0 and db.row_counts()["occupancy_coarse"] == 10 * 3


def test_everything_goes_after_its_own_retention(db: HistoryDatabase) -> None:
    batch = Batch()
    for k in (0, 100):
        batch.add_occupancy(occupancy(B + k * MIN, 3))
        batch.add_track_sample(tracks(B + k * MIN, {k + 1: (0.0, 0.0)}, zones={k + 1: ["gate"]}))
    batch.add_event(violation("old", B, end_ns=B + S))
    batch.add_event(violation("never-ended", B + S))
    batch.add_event(violation("recent", B + 100 * MIN, pair=(3, 4)))
    db.write(batch)
    db.acknowledge("old", "ann", B + 2 * S)
    policy = RetentionPolicy(fine_s=60, occupancy_s=50 * 60, events_s=50 * 60, tracks_s=50 * 60)
    result = db.apply_retention(policy, now_ns=B + 100 * MIN + S)
    assert result.done
    assert [(p.time_ns - B) // MIN for p in db.occupancy()] == [100]
    assert [s.track_id for s in db.track_summaries()[0]] == [101]
    assert db.trajectory(1) is None
    assert [e.id for e in db.events(EventFilter(), 10)[0]] == ["recent"]
    counts = db.row_counts()
    assert counts["acknowledgements"] == 0 and counts["event_tracks"] == 2 and counts["track_zones"] == 1
    assert counts["track_points"] == 1
    assert db.apply_retention(policy, now_ns=B + 100 * MIN + S).deleted == {
        "occupancy_coarse": 0, "track_points": 0, "tracks": 0, "events": 0}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"fine_s": 0}, "fine_s must be positive"),
        ({"tracks_s": -1}, "tracks_s must be positive"),
        ({"coarse_step_s": 7}, "coarse_step_s must divide a day"),
        ({"fine_s": 10, "occupancy_s": 5}, "must not exceed occupancy_s"),
    ],
)
def test_policy_errors(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        RetentionPolicy(**kwargs)


def test_the_recorders_policy_is_kept_for_readers(db: HistoryDatabase) -> None:
    assert db.retention() is None
    policy = RetentionPolicy(fine_s=3600, occupancy_s=86400 * 90, tracks_s=86400 * 7)
    db.save_retention(policy)
    db.save_retention(policy)  # saved again at every start
    assert db.retention() == policy


FAR_FUTURE = 2**63 - 1


def test_rows_beyond_the_trusted_bound_are_purged_and_the_rest_kept(db: HistoryDatabase) -> None:
    """Rows a forged far-future message wrote never age out by themselves; retention removes them
    and pulls a real track's last sighting back to its newest true position."""
    batch = Batch()
    for t in (B, B + S):
        batch.add_track_sample(tracks(t, {1: (0.0, 0.0)}))
        batch.add_occupancy(occupancy(t, 1, gate=1))
    batch.add_track_sample(tracks(FAR_FUTURE, {1: (5.0, 5.0), 666: (1.0, 1.0)}))
    batch.add_occupancy(occupancy(FAR_FUTURE, 99, gate=99))
    batch.add_event(violation("forged", FAR_FUTURE))
    batch.add_event(violation("real", B))
    db.write(batch)
    result = db.apply_retention(RetentionPolicy(), now_ns=B + 10 * S, latest_ns=B + 15 * S)
    assert result.deleted["future"] > 0
    assert [s.track_id for s in db.track_summaries()[0]] == [1]
    assert db.track_summaries()[0][0].last_ns == B + S
    assert db.newest_track_time_ns() == B + S and db.newest_occupancy_ns() == B + S
    assert [e.id for e in db.events(EventFilter(), 10)[0]] == ["real"]
    assert db.apply_retention(RetentionPolicy(), now_ns=B + 10 * S, latest_ns=B + 15 * S).deleted["future"] == 0
