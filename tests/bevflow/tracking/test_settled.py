"""Tracks settled one update late: a new person's first update, a missed update bridged, and
nothing else changed."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import bevflow.tracking.settled
from bevflow.detections import Cylinders
from bevflow.tracking.settled import SettledFrame, SettledTracks
from bevflow.tracking.tracker import Tracker, TrackerConfig, TrackTable

NOBODY = np.zeros((0, 2))


def _run(config: TrackerConfig, seen: list[np.ndarray], times: list[float]) -> tuple[list[TrackTable], list[SettledFrame]]:
    """The online output and the settled frames (flushed at the end) of one tracker over ``seen``."""
    tracker, late = Tracker(config), SettledTracks()
    online, settled = [], []
    for xy, t in zip(seen, times, strict=True):
        online.append(tracker.update(Cylinders(xy=xy), t))
        settled.append(late.push(tracker.tracks(include_tentative=True), t))
    assert settled[0] is None
    return online, [*settled[1:], late.flush()]


def _reported(frames: list[SettledFrame]) -> list[list[int]]:
    return [f.tracks.id.tolist() for f in frames]


WALKER = [np.array([[0.5 * k, 0.0]]) for k in range(6)]  # 0.5 m per update


@pytest.mark.parametrize(
    ("config", "seen", "times", "online_ids", "settled_ids"),
    [
        # Confirmed on the 2nd detection: the 1st is reported late, under the id it got.
        (TrackerConfig(activate_hits=2), WALKER, [0.0, 0.5, 1.0, 1.5, 2.0, 2.5], [[], [1], [1], [1], [1], [1]], [[1]] * 6),
        # On the 3rd: one update late settles only the 2nd.
        (TrackerConfig(activate_hits=3), WALKER, [0.0, 0.5, 1.0, 1.5, 2.0, 2.5], [[], [], [1], [1], [1], [1]],
         [[], [1], [1], [1], [1], [1]]),
        # Missed once and found again: bridged (the online tracker reports it coasting as well).
        (TrackerConfig(activate_hits=2), [*WALKER[:3], NOBODY, *WALKER[4:]], [0.0, 0.5, 1.0, 1.5, 2.0, 2.5],
         [[], [1], [1], [1], [1], [1]], [[1]] * 6),
        # Missed and never found again: the online tracker reports it coasting, the settled output does not.
        (TrackerConfig(activate_hits=2), [*WALKER[:3], NOBODY, NOBODY, NOBODY], [0.0, 0.5, 1.0, 1.5, 2.0, 2.5],
         [[], [1], [1], [1], [], []], [[1], [1], [1], [], [], []]),
        # Missed twice: one update late cannot tell, so the gap stays.
        (TrackerConfig(activate_hits=2, report_max_misses=0), [*WALKER[:2], NOBODY, NOBODY, *WALKER[4:]],
         [0.0, 0.5, 1.0, 1.5, 2.0, 2.5], [[], [1], [], [], [1], [1]], [[1], [1], [], [], [1], [1]]),
        # Seen once (a false positive): never a track, never reported.
        (TrackerConfig(activate_hits=2), [WALKER[0], NOBODY, NOBODY], [0.0, 0.5, 1.0], [[], [], []], [[], [], []]),
    ],
    ids=["first-update", "three-hits", "missed-once", "gone", "missed-twice", "one-off"],
)
def test_what_the_next_update_settles(config, seen, times, online_ids, settled_ids) -> None:  # noqa: ANN001
    online, settled = _run(config, seen, times)
    assert [t.id.tolist() for t in online] == online_ids
    assert _reported(settled) == settled_ids
    assert [f.time_s for f in settled] == times


def test_a_missed_update_lies_between_its_neighbours_in_time() -> None:
    # Standing at the origin until 0.5 s, missed at 1.0 s, found at 2.0 s: the missed update is a
    # third of the way in time from the one before to the one after.
    config = TrackerConfig(activate_hits=1, measurement_std_m=1e-4)
    seen = [np.array([[0.0, 0.0]]), np.array([[0.0, 0.0]]), NOBODY, np.array([[0.6, 0.9]])]
    _, settled = _run(config, seen, [0.0, 0.5, 1.0, 2.0])
    np.testing.assert_allclose(settled[2].tracks.xy, [[0.2, 0.3]], atol=1e-3)


def test_matched_tracks_are_reported_as_the_online_tracker_reported_them() -> None:
    rng = np.random.default_rng(3)
    people = rng.uniform(-10, 10, (12, 2))
    seen = [people + rng.normal(0, 0.1, people.shape) + [0.3 * k, 0.0] for k in range(8)]
    seen = [xy[rng.random(len(xy)) > 0.2] for xy in seen]  # a fifth missed each update
    times = [0.5 * k for k in range(8)]
    online, settled = _run(TrackerConfig(activate_hits=2), seen, times)
    for table, frame in zip(online, settled, strict=True):
        matched = table.misses == 0
        assert set(table.id[matched].tolist()) <= set(frame.tracks.id.tolist())
        for track_id, xy in zip(table.id[matched], table.xy[matched], strict=True):
            np.testing.assert_array_equal(frame.tracks.xy[frame.tracks.id == track_id], [xy])


def test_flush_starts_afresh() -> None:
    tracker, late = Tracker(TrackerConfig(activate_hits=1)), SettledTracks()
    tracker.update(Cylinders(xy=WALKER[0]), 0.0)
    assert late.push(tracker.tracks(include_tentative=True), 0.0) is None
    assert late.flush().tracks.id.tolist() == [1]
    assert late.flush() is None
    tracker.update(Cylinders(xy=WALKER[1]), 0.5)
    assert late.push(tracker.tracks(include_tentative=True), 0.5) is None  # nothing held over


def test_push_each_pushes_in_turn_and_keeps_what_was_settled() -> None:
    tracker, updates = Tracker(TrackerConfig(activate_hits=1)), []
    for t, xy in zip((0.0, 0.5, 1.0), WALKER, strict=False):
        tracker.update(Cylinders(xy=xy), t)
        updates.append((t, tracker.tracks(include_tentative=True)))
    one_by_one, late = SettledTracks(), SettledTracks()
    expected = [frame.tracks for t, tracks in updates if (frame := one_by_one.push(tracks, t)) is not None]
    got = late.push_each(updates)
    assert len(got) == len(expected) == 2 and late.push_each([]) == []
    assert [g.id.tolist() for g in got] == [e.id.tolist() for e in expected]
    assert late.flush().tracks.id.tolist() == one_by_one.flush().tracks.id.tolist() == [1]


def test_every_track_has_a_key_of_its_own_for_the_life_of_the_tracker() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=2))
    tracker.update(Cylinders(xy=[[0.0, 0.0], [5.0, 0.0]]), 0.0)
    first = tracker.tracks(include_tentative=True)
    tracker.update(Cylinders(xy=[[0.1, 0.0], [9.0, 0.0]]), 0.5)  # one confirmed, one born, one tentative missed
    second = tracker.tracks(include_tentative=True)
    tracker.reset()
    tracker.update(Cylinders(xy=[[0.0, 0.0]]), 1.0)
    third = tracker.tracks(include_tentative=True)
    assert first.key.tolist() == [0, 1] and first.id.tolist() == [-1, -1]
    assert second.key.tolist() == [0, 1, 2] and second.id.tolist() == [1, -1, -1]
    assert third.key.tolist() == [3]


def test_docstring_example() -> None:
    assert doctest.testmod(bevflow.tracking.settled).failed == 0
