from __future__ import annotations

import numpy as np
import pytest

from bevflow.analytics.trajectories import TrackHistory
from bevflow.schemas import TrajectoryPoint

S = 1_000_000_000
Q = S // 4  # ticks every 0.25 s


def test_one_sample_per_period_on_shared_ticks() -> None:
    history = TrackHistory(sample_period_s=1.0)
    stored = []
    for k in range(10):  # 0 .. 2.25 s
        people = {7: (k * 0.1, 0.0)}
        if k >= 2:  # track 8 appears at 0.5 s, mid-period: it waits for the next sampled tick
            people[8] = (5.0, k * 1.0)
        stored.append(history.update(k * Q, list(people), list(people.values())))
    assert stored == [True, False, False, False, True, False, False, False, True, False]
    assert history.trajectory(7).times_ns.tolist() == [0, S, 2 * S]
    np.testing.assert_allclose(history.trajectory(7).xy, [[0.0, 0.0], [0.4, 0.0], [0.8, 0.0]], atol=1e-6)
    assert history.trajectory(8).times_ns.tolist() == [S, 2 * S]
    assert history.trajectory(8).xy[:, 1].tolist() == [4.0, 8.0]


def test_ring_buffer_keeps_the_newest_points_in_order() -> None:
    history = TrackHistory(max_points=5, sample_period_s=0)
    for k in range(23):
        history.update(k * S, [1], [[float(k), 0.0]])
    trajectory = history.trajectory(1)
    assert trajectory.times_ns.tolist() == [18 * S, 19 * S, 20 * S, 21 * S, 22 * S]
    assert trajectory.xy[:, 0].tolist() == [18.0, 19.0, 20.0, 21.0, 22.0]
    assert trajectory.to_points()[0] == TrajectoryPoint(time_ns=18 * S, xy=(18.0, 0.0))


def test_memory_is_bounded_under_track_churn() -> None:
    history = TrackHistory(max_points=50, sample_period_s=0, max_tracks=16, retire_after_s=1e6)
    bound = 16 * 50 * (8 + 2 * 4)  # int64 time + two float32 coordinates per sample
    for k in range(2000):  # 2,000 ticks, 5 people at a time, a new track every tick
        ids = np.arange(k, k + 5)
        history.update(k * S, ids, np.zeros((5, 2)))
        assert len(history) <= 16
    assert history.nbytes <= bound
    assert history.track_ids.tolist() == list(range(1988, 2004))  # the 16 seen most recently
    assert history.skipped == 0


def test_tracks_unseen_for_a_while_are_retired() -> None:
    history = TrackHistory(sample_period_s=0, retire_after_s=10)
    history.update(0, [1, 2], [[0, 0], [1, 1]])
    history.update(5 * S, [2], [[1, 1]])
    history.update(10 * S, [2], [[1, 1]])
    assert 1 in history
    history.update(11 * S, [2], [[1, 1]])
    assert 1 not in history and 2 in history
    with pytest.raises(KeyError, match="no history for track 1"):
        history.trajectory(1)


def test_full_table_evicts_the_track_seen_least_recently() -> None:
    history = TrackHistory(sample_period_s=0, max_tracks=2)
    history.update(0, [1], [[0, 0]])
    history.update(1 * S, [2], [[0, 0]])
    history.update(2 * S, [3], [[0, 0]])
    assert history.track_ids.tolist() == [2, 3]
    history.update(3 * S, [4, 5, 6], [[0, 0], [1, 1], [2, 2]])  # more at once than the table holds
    assert len(history) == 2 and history.skipped == 1


def test_samples_flatten_every_trajectory() -> None:
    history = TrackHistory(max_points=3, sample_period_s=0)
    for k in range(5):
        ids = [4, 9] if k % 2 else [4]
        history.update(k * S, ids, [[k, 0.0], [0.0, k]][: len(ids)])
    ids, times, xy = history.samples()
    rows = sorted(zip(ids.tolist(), times.tolist(), xy.tolist(), strict=True))
    assert rows == [
        (4, 2 * S, [2.0, 0.0]),
        (4, 3 * S, [3.0, 0.0]),
        (4, 4 * S, [4.0, 0.0]),
        (9, 1 * S, [0.0, 1.0]),
        (9, 3 * S, [0.0, 3.0]),
    ]


@pytest.mark.parametrize(
    ("options", "message"),
    [({"max_points": 0}, "at least 1"), ({"max_tracks": 0}, "at least 1"), ({"retire_after_s": 0}, "retire_after_s")],
)
def test_bad_options_are_refused(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TrackHistory(**options)
