from __future__ import annotations

import pytest

from bevflow_services.storage import SITE, Batch, TrackSampler
from tests.services.gateway.feed import S, T0, occupancy, tracks, violation

MS = 1_000_000


def test_occupancy_keeps_the_highest_count_per_second_and_zone() -> None:
    batch = Batch()
    for offset_ms, total, gate in [(0, 3, 1), (400, 7, 0), (900, 5, 2), (1000, 2, 2)]:
        batch.add_occupancy(occupancy(T0 + offset_ms * MS, total, gate=gate))
    assert batch.occupancy == {
        (T0, SITE): 7, (T0, "gate"): 2, (T0, "shop"): 0,
        (T0 + S, SITE): 2, (T0 + S, "gate"): 2, (T0 + S, "shop"): 0,
    }


@pytest.mark.parametrize(
    ("first_end", "second_end", "kept_end"),
    [
        (None, T0 + S, T0 + S),  # the end replaces the start
        (T0 + S, None, T0 + S),  # a replayed start never reopens an ended alert
        (None, None, None),
        (T0 + S, T0 + S, T0 + S),
    ],
)
def test_an_alert_keeps_its_latest_state(first_end, second_end, kept_end) -> None:
    batch = Batch()
    batch.add_event(violation("v1", T0, end_ns=first_end))
    batch.add_event(violation("v1", T0, end_ns=second_end))
    assert list(batch.events) == ["v1"] and batch.events["v1"].end_ns == kept_end


def test_track_samples_record_positions_time_spans_and_zones() -> None:
    batch = Batch()
    batch.add_track_sample(tracks(T0, {1: (0.5, 1.0), 2: (3.0, 0.0)}, zones={1: ["gate"]}))
    batch.add_track_sample(tracks(T0 + S, {1: (0.7, 1.0)}, zones={1: ["gate", "shop"]}))
    assert batch.points == {(1, T0): (0.5, 1.0), (2, T0): (3.0, 0.0), (1, T0 + S): (0.7, 1.0)}
    assert batch.tracks == {1: (T0, T0 + S), 2: (T0, T0)}
    assert batch.track_zones == {(1, "gate"): (T0, T0 + S), (1, "shop"): (T0 + S, T0 + S)}
    assert len(batch) == 3


def test_merge_combines_an_older_failed_batch_with_a_newer_one() -> None:
    older, newer = Batch(), Batch()
    older.add_occupancy(occupancy(T0, 9))
    older.add_event(violation("v1", T0, end_ns=T0 + S))
    older.add_track_sample(tracks(T0, {1: (0.0, 0.0)}))
    newer.add_occupancy(occupancy(T0 + 100 * MS, 4))
    newer.add_event(violation("v1", T0))  # replayed start, arriving after its end
    newer.add_event(violation("v2", T0 + S))
    newer.add_track_sample(tracks(T0 + S, {1: (1.0, 0.0)}))
    older.merge(newer)
    assert older.occupancy[(T0, SITE)] == 9
    assert {k: e.end_ns for k, e in older.events.items()} == {"v1": T0 + S, "v2": None}
    assert older.tracks == {1: (T0, T0 + S)}
    assert len(older.points) == 2


def test_dropping_for_memory_takes_the_oldest_samples_and_never_alerts() -> None:
    batch = Batch()
    for k in range(5):
        batch.add_occupancy(occupancy(T0 + k * S, k))  # three rows per second
        batch.add_track_sample(tracks(T0 + k * S, {1: (float(k), 0.0)}))
        batch.add_event(violation(f"v{k}", T0 + k * S))
    dropped = batch.drop_oldest_samples(keep=6)
    assert dropped == 15 - 6  # three occupancy rows a second; the five positions fit
    assert sorted({t for t, _ in batch.occupancy}) == [T0 + 3 * S, T0 + 4 * S]
    assert len(batch.points) == 5 and len(batch.events) == 5


@pytest.mark.parametrize(
    ("last_sampled", "times_ms", "kept_ms"),
    [
        (None, [0, 100, 999, 1000, 1500, 3200], [0, 1000, 3200]),
        (T0 + 500 * MS, [600, 999, 1000, 1100], [1000]),  # resumes after a restart mid-second
    ],
)
def test_the_sampler_keeps_the_first_tick_of_each_period(last_sampled, times_ms, kept_ms) -> None:
    sampler = TrackSampler(1.0, last_sampled)
    assert [t for t in times_ms if sampler.keep(T0 + t * MS)] == kept_ms


def test_the_sampler_refuses_a_period_that_is_not_positive() -> None:
    with pytest.raises(ValueError, match="period_s must be positive"):
        TrackSampler(0.0)
