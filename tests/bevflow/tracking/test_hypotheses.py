"""Several hypotheses held open: crossings the plain tracker swaps, decisions made final a window
late and exactly once, ids never shared, and the settings that choose the tracker."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.detections import Cylinders
from bevflow.site import Thresholds
from bevflow.tracking import hypotheses as hypotheses_module
from bevflow.tracking.hypotheses import HypothesisTracker, _PublishedIds, online_tracker
from bevflow.tracking.tracker import Tracker, TrackerConfig

FPS = 4.0
NOISE_M = 0.12


def _crossing(tracker: Tracker | HypothesisTracker, seed: int) -> bool:
    """Two people cross diagonally 0.4 m/s apart in y at 4 fps, each seen 0.12 m off (σ): does
    each keep the id they had before the crossing to the end?"""
    rng = np.random.default_rng(seed)
    times = np.arange(16) / FPS
    people = np.stack([np.stack([0.8 * times, 0.5 * times], 1), np.stack([0.8 * times, 1.0 - 0.5 * times], 1)], 1)
    covariance = np.broadcast_to((NOISE_M**2 + 0.05**2) * np.eye(2), (2, 2, 2))
    ids = []
    for xy, t in zip(people, times, strict=True):
        table = tracker.update(Cylinders(xy=xy + rng.normal(0, NOISE_M, (2, 2)), covariance=covariance), float(t))
        if len(table) == 2:
            nearest = np.linalg.norm(table.xy[:, None] - xy[None], axis=2).argmin(axis=0)
            ids.append(tuple(table.id[nearest].tolist()))
    return ids[0] == ids[-1]


def test_crossings_the_plain_tracker_swaps_are_held() -> None:
    seeds = range(30)
    plain = [_crossing(Tracker(TrackerConfig(activate_hits=1)), s) for s in seeds]
    held = [_crossing(HypothesisTracker(TrackerConfig(activate_hits=1, hypotheses=20)), s) for s in seeds]
    assert not all(plain)  # the scene does swap identities one update at a time
    assert all(held) and sum(held) > sum(plain)


def _crowd(seed: int, frames: int = 24) -> list[Cylinders]:
    """Six people milling about a 2 m square, seen 0.1 m off, one in ten missed."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 2, (6, 2))
    velocity = rng.normal(0, 0.5, (6, 2))
    out = []
    for _ in range(frames):
        xy = xy + velocity / FPS
        velocity += rng.normal(0, 0.3, (6, 2))
        seen = rng.random(6) > 0.1
        out.append(Cylinders(xy=(xy + rng.normal(0, 0.1, xy.shape))[seen], covariance=np.broadcast_to(0.01 * np.eye(2), (int(seen.sum()), 2, 2))))
    return out


def test_every_update_is_made_final_once_in_order_a_window_late() -> None:
    config = TrackerConfig(hypotheses=10, hypothesis_window_s=1.0)
    tracker = HypothesisTracker(config, keep_final=True)
    final = []
    for k, cylinders in enumerate(_crowd(1)):
        tracker.update(cylinders, k / FPS)
        made = tracker.final()
        assert all(t <= k / FPS - config.hypothesis_window_s for t, _ in made)
        final += made
    assert len(final) < 24
    final += tracker.finish()
    assert [t for t, _ in final] == [k / FPS for k in range(24)]
    assert tracker.final() == [] and tracker.finish() == []


def test_a_live_tracker_keeps_no_final_updates() -> None:
    tracker = HypothesisTracker(TrackerConfig(hypotheses=10, hypothesis_window_s=1.0))  # as a site runs it
    for k, cylinders in enumerate(_crowd(1)):
        tracker.update(cylinders, k / FPS)
    assert tracker._final == []  # nothing piles up for a reader that never comes
    with pytest.raises(ValueError, match="keep_final"):
        tracker.final()


@pytest.mark.parametrize("seed", range(3))
def test_an_id_is_never_given_to_two_tracks(seed: int) -> None:
    tracker = HypothesisTracker(TrackerConfig(hypotheses=10, activate_hits=2), first_id=50, keep_final=True)
    key_of: dict[int, int] = {}
    reported: set[int] = set()
    for k, cylinders in enumerate(_crowd(seed)):
        table = tracker.update(cylinders, k / FPS)
        assert len(set(table.id.tolist())) == len(table)
        reported.update(table.id.tolist())
        for _, tracks in tracker.final():
            for i, key in zip(tracks.id.tolist(), tracks.key.tolist(), strict=True):
                if i >= 0:
                    assert key_of.setdefault(i, key) == key
                    reported.add(i)
    # reported ids count the tracks reported, from first_id on, whatever the hypotheses spent
    assert sorted(reported) == list(range(50, tracker.next_id)) and set(key_of) <= reported


def test_reset_forgets_tracks_but_keeps_counting_ids() -> None:
    tracker = HypothesisTracker(TrackerConfig(hypotheses=5, activate_hits=1))
    first = tracker.update(Cylinders(xy=[[0.0, 0.0]]), 0.0)
    tracker.reset()
    assert tracker.time_s is None and len(tracker.tracks(include_tentative=True)) == 0
    again = tracker.update(Cylinders(xy=[[0.0, 0.0]]), 0.0)
    assert again.id.tolist() == [first.id[0] + 1]


def test_the_plain_tracker_unless_hypotheses_are_asked_for() -> None:
    assert type(online_tracker(TrackerConfig())) is Tracker
    assert type(online_tracker(TrackerConfig.from_thresholds(Thresholds(track_hypotheses=1)))) is Tracker
    assert type(online_tracker(TrackerConfig.from_thresholds(Thresholds()))) is HypothesisTracker  # a site's default
    views = TrackerConfig.from_thresholds(Thresholds(track_views=True))
    assert type(online_tracker(views, fuse=lambda seen: seen)) is HypothesisTracker


@pytest.mark.parametrize(
    ("people", "hypotheses", "budget", "room"),
    [
        pytest.param(4, 20, 2000, 20, id="few people: as many as asked"),
        pytest.param(4, 20, 40, 10, id="budget over people"),
        pytest.param(4, 3, 40, 3, id="never more than asked"),
        pytest.param(30, 20, 40, 1, id="a crowd past the budget: one"),
    ],
)
def test_hypotheses_kept_shrink_as_tracks_outgrow_the_budget(monkeypatch, people: int, hypotheses: int,
                                                            budget: int, room: int) -> None:  # fmt: skip
    monkeypatch.setattr(hypotheses_module, "HYPOTHESIS_TRACKS", budget)
    tracker = HypothesisTracker(TrackerConfig(activate_hits=1, hypotheses=hypotheses))
    rng = np.random.default_rng(people)
    xy = np.stack([np.arange(people) * 0.6, np.zeros(people)], 1)  # a queue, 0.6 m apart: choices to branch on
    held = []
    for k in range(8):
        tracker.update(Cylinders(xy=xy + rng.normal(0, 0.15, xy.shape)), k / FPS)
        held.append(len(tracker._hypotheses))
    assert max(held) == room  # reached, never passed
    assert len(tracker.best) == people and tracker.room() == room


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        pytest.param({"hypotheses": 0}, "hypotheses", id="none"),
        pytest.param({"hypotheses": 2, "gate_chi2": None}, "gate_chi2", id="no uncertainty gate"),
        pytest.param({"hypothesis_window_s": 0.0}, "hypothesis_window_s", id="no window"),
    ],
)
def test_settings_refused(overrides: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TrackerConfig(**overrides)


def test_branching_leaves_the_tracker_where_it_was_and_copies_share_the_ids() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1))
    tracker.update(Cylinders(xy=[[0.0, 0.0], [0.5, 0.0]]), 0.0)
    before = tracker.tracks(include_tentative=True)
    branches = tracker.branch(Cylinders(xy=[[0.25, 0.0], [0.3, 0.0], [3.0, 3.0]]), 0.25, count=5, within=50.0)
    children = [branches.child(choice) for choice in branches.choices]
    after = tracker.tracks(include_tentative=True)
    assert tracker.time_s == 0.0 and np.array_equal(before.xy, after.xy)
    costs = [choice.cost for choice in branches.choices]
    assert len(costs) > 1 and costs == sorted(costs)
    born = [(table := child.report()).id[table.detection == 2].tolist() for child in children]
    assert born[0] == [3] and born[1] == [4]  # one counter for every copy
    with pytest.raises(ValueError, match="gate_chi2"):
        Tracker(TrackerConfig(gate_chi2=None)).branch(Cylinders.empty(), 0.0, count=2, within=1.0)


def test_reported_ids_of_tracks_no_hypothesis_holds_are_forgotten_once_the_table_doubles() -> None:
    published = _PublishedIds(next_id=1)
    table = Tracker(TrackerConfig(activate_hits=1)).update(Cylinders(xy=np.zeros((300, 2)) + np.arange(300)[:, None]), 0.0)
    assert published.publish(table).id.tolist() == list(range(1, 301))
    asked = []
    published.forget_unless(lambda: asked.append(1) or {1, 2})
    assert asked == [1] and published.ids == {1: 1, 2: 2}
    published.forget_unless(lambda: asked.append(1) or set())  # not due: 2 entries, kept 2
    assert asked == [1] and published.publish(table[:3]).id.tolist() == [1, 2, 301]
