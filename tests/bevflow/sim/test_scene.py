from __future__ import annotations

from collections import defaultdict
from dataclasses import replace

import numpy as np
import pytest

from bevflow.sim.bodies import Posture
from bevflow.sim.scene import (
    BODY_RADIUS,
    Door,
    GoalArea,
    Navigator,
    Obstacles,
    Pillar,
    Scene,
    SceneConfig,
    SceneFrame,
    Shelf,
)

ROOM = SceneConfig(
    floor=(0.0, 0.0, 12.0, 8.0),
    pillars=(Pillar(4.0, 4.0, 0.4, 3.0), Pillar(8.0, 2.5, 0.3, 3.0)),
    shelves=(Shelf(6.5, 5.0, 9.5, 5.8, 1.6),),
    entries=(Door(0.0, 4.0, 1.5), Door(12.0, 6.0, 1.5)),
    identities=6,
    group_fraction=0.0,
    goals_per_visit=(1, 2),
    absence_s=(1.0, 3.0),
    frames=400,
    seed=5,
)


def run(config: SceneConfig) -> list[SceneFrame]:
    return list(Scene(config).run())


def tracks(frames: list[SceneFrame]) -> dict[int, list[tuple[int, np.ndarray, int]]]:
    """person id → [(frame index, feet xy, identity)]"""
    out: dict[int, list] = defaultdict(list)
    for f in frames:
        for pid, xy, ident in zip(f.person_ids, f.feet_xy, f.identity, strict=True):
            out[int(pid)].append((f.index, xy, int(ident)))
    return out


def test_same_seed_same_frames_and_another_seed_differs() -> None:
    config = replace(ROOM, frames=120)
    a, b = run(config), run(config)
    assert len(a) == len(b) == 120
    for fa, fb in zip(a, b, strict=True):
        for name in ("person_ids", "identity", "group", "feet_xy", "heading", "gait_phase", "speed", "posture"):
            np.testing.assert_array_equal(getattr(fa, name), getattr(fb, name))
        np.testing.assert_array_equal(fa.body.height, fb.body.height)
    other = run(replace(config, seed=6))
    assert not np.array_equal(a[50].feet_xy, other[50].feet_xy)


def test_a_scene_can_be_run_twice_with_identical_results() -> None:
    scene = Scene(replace(ROOM, frames=30))
    first, second = list(scene.run()), list(scene)
    np.testing.assert_array_equal(first[-1].feet_xy, second[-1].feet_xy)


def test_time_follows_the_frame_rate() -> None:
    frames = run(replace(ROOM, frames=5, fps=4.0))
    assert [f.time_s for f in frames] == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert [f.index for f in frames] == [0, 1, 2, 3, 4]


def test_people_never_stand_inside_obstacles_walls_or_each_other() -> None:
    config = replace(ROOM, identities=None, people=14, group_fraction=0.3, frames=300)
    obstacles = Obstacles(config.pillars, config.shelves)
    closest = np.inf
    for f in run(config):
        assert len(f)
        dist, _ = obstacles.signed_distance(f.feet_xy)
        assert dist.min() >= BODY_RADIUS - 1e-9
        lo, hi = np.array([0.0, 0.0]) + BODY_RADIUS - 1e-9, np.array([12.0, 8.0]) - BODY_RADIUS + 1e-9
        assert np.all((f.feet_xy >= lo) & (f.feet_xy <= hi))
        if len(f) > 1:
            gaps = np.linalg.norm(f.feet_xy[:, None] - f.feet_xy[None], axis=-1) + np.eye(len(f)) * 9
            closest = min(closest, gaps.min())
    assert closest > 0.35  # bodies are about 0.45 m across


def test_people_walk_at_human_speeds() -> None:
    frames = run(replace(ROOM, frames=200))
    speed = np.concatenate([f.speed for f in frames])
    moving = speed[speed > 0.3]
    assert 0.9 < np.median(moving) < 1.6
    assert np.percentile(speed, 99) < 2.4


def test_leaving_and_coming_back_gives_a_new_id_for_the_same_identity() -> None:
    frames = run(ROOM)
    by_id = tracks(frames)
    assert len(by_id) > ROOM.identities  # some came back
    identities = {pid: {i for _, _, i in rows} for pid, rows in by_id.items()}
    assert all(len(ids) == 1 for ids in identities.values())
    assert set().union(*identities.values()) <= set(range(ROOM.identities))
    for rows in by_id.values():  # an id is present in one unbroken stretch of frames
        index = [r[0] for r in rows]
        assert index == list(range(index[0], index[0] + len(index)))
    for f in frames:  # nobody is inside twice at once
        assert len(set(f.identity.tolist())) == len(f)
    # The body belongs to the identity: same stature on every visit.
    stature: dict[int, set[float]] = defaultdict(set)
    for f in frames:
        for ident, h in zip(f.identity, f.body.height, strict=True):
            stature[int(ident)].add(float(h))
    assert all(len(h) == 1 for h in stature.values())


def test_people_appear_at_entries_and_vanish_at_exits() -> None:
    frames = run(ROOM)
    doors = np.array([[d.x, d.y] for d in ROOM.entries])
    last = frames[-1].index
    starts = ends = 0
    for rows in tracks(frames).values():
        first_index, first_xy, _ = rows[0]
        last_index, last_xy, _ = rows[-1]
        if first_index > 0:
            assert np.linalg.norm(doors - first_xy, axis=1).min() < 1.3
            starts += 1
        if last_index < last:
            assert np.linalg.norm(doors - last_xy, axis=1).min() < 1.3
            ends += 1
    assert starts > 0 and ends > 0


def test_without_doors_nobody_leaves() -> None:
    frames = run(replace(ROOM, entries=(), frames=300))
    assert all(f.person_ids.tolist() == frames[0].person_ids.tolist() for f in frames)


def test_groups_walk_together() -> None:
    config = replace(ROOM, identities=8, group_fraction=1.0, frames=300, seed=2)
    frames = run(config)
    spreads = []
    for f in frames:
        for g in set(f.group.tolist()) - {-1}:
            members = f.feet_xy[f.group == g]
            if len(members) > 1:
                spreads.append(np.linalg.norm(members - members.mean(0), axis=1).max())
    assert len(spreads) > 100
    assert np.percentile(spreads, 95) < 2.0
    sizes = [np.sum(frames[0].group == g) for g in set(frames[0].group.tolist()) - {-1}]
    assert sizes and all(2 <= s <= 4 for s in sizes)


def test_goals_lie_in_the_goal_areas() -> None:
    area = ((1.0, 1.0), (3.0, 1.0), (3.0, 3.0), (1.0, 3.0))
    config = replace(ROOM, pillars=(), shelves=(), entries=(), goal_areas=(GoalArea(area),), frames=300, identities=4)
    frames = run(config)
    # Dwelling and slow people are at goals; by the end everyone has walked into the area at least once.
    late = np.concatenate([f.feet_xy for f in frames[150:]])
    inside = np.all((late > 0.5) & (late < 3.5), axis=1)
    assert inside.mean() > 0.8


@pytest.mark.parametrize(
    ("standing", "sitting", "expected"), [(1.0, 0.0, Posture.STANDING), (0.0, 1.0, Posture.SITTING)]
)
def test_some_people_stop_to_stand_or_sit(standing: float, sitting: float, expected: Posture) -> None:
    config = replace(ROOM, standing_fraction=standing, sitting_fraction=sitting, dwell_probability=0.0, frames=300)
    frames = run(config)
    posture = np.concatenate([f.posture for f in frames])
    assert (posture == expected).mean() > 0.2
    if expected == Posture.SITTING:  # seated people do not drift
        seat: dict[int, np.ndarray] = {}
        for f in frames:
            sitting = f.posture == Posture.SITTING
            for pid in set(seat) - set(f.person_ids[sitting].tolist()):
                del seat[pid]  # got up
            for pid, xy in zip(f.person_ids[sitting], f.feet_xy[sitting], strict=True):
                np.testing.assert_array_equal(seat.setdefault(int(pid), xy), xy)


def test_routes_go_around_obstacles() -> None:
    obstacles = Obstacles((Pillar(5.0, 5.0, 1.0, 3.0),), (Shelf(2.0, 7.0, 8.0, 8.0, 1.5),))
    nav = Navigator((0.0, 0.0, 10.0, 10.0), obstacles)
    start, goal = np.array([1.0, 5.0]), np.array([9.0, 5.0])
    assert obstacles.blocks_segments(start[None], goal[None], 0.0)[0]
    route = nav.route(start, goal)
    np.testing.assert_array_equal(route[-1], goal)
    legs = np.array([start, *route])
    assert not obstacles.blocks_segments(legs[:-1], legs[1:], BODY_RADIUS).any()
    length = np.linalg.norm(np.diff(legs, axis=0), axis=1).sum()
    assert 8.0 < length < 9.5  # a short detour, not the long way round the shelf
    assert nav.route(np.array([1.0, 1.0]), np.array([9.0, 1.0]))[0].tolist() == [9.0, 1.0]  # clear: straight


@pytest.mark.parametrize(
    ("point", "pillar", "shelf", "pillar_away", "shelf_away"),
    [
        ((5.0, 5.0), -1.0, 2.0, (1.0, 0.0), (0.0, -1.0)),  # at the pillar's centre, below the shelf
        ((7.0, 5.0), 1.0, 2.0, (1.0, 0.0), (0.0, -1.0)),
        ((2.5, 7.5), 2.5 * 2**0.5 - 1.0, -0.5, (-(0.5**0.5), 0.5**0.5), (-1.0, 0.0)),  # inside the shelf
        ((9.0, 9.0), 4 * 2**0.5 - 1.0, 2**0.5, (0.5**0.5, 0.5**0.5), (0.5**0.5, 0.5**0.5)),  # off its corner
    ],
)
def test_signed_distance_to_footprints(point, pillar, shelf, pillar_away, shelf_away) -> None:
    obstacles = Obstacles((Pillar(5.0, 5.0, 1.0, 3.0),), (Shelf(2.0, 7.0, 8.0, 8.0, 1.5),))
    dist, away = obstacles.signed_distance(np.array([point]))
    np.testing.assert_allclose(dist[0], [pillar, shelf], atol=1e-12)
    np.testing.assert_allclose(away[0], [pillar_away, shelf_away], atol=1e-12)


PILLAR_ONLY = Obstacles((Pillar(5.0, 5.0, 1.0, 3.0),))
SHELF_ONLY = Obstacles(shelves=(Shelf(2.0, 7.0, 8.0, 8.0, 1.5),))


@pytest.mark.parametrize(
    ("obstacles", "origin", "end", "hits"),
    [
        (PILLAR_ONLY, (2.0, 5.0, 3.3), (5.0, 5.0, 0.0), True),  # the pillar's foot
        (PILLAR_ONLY, (2.0, 5.0, 3.3), (7.0, 5.0, 0.0), True),  # behind the pillar
        (PILLAR_ONLY, (2.0, 5.0, 3.3), (7.0, 5.0, 3.1), False),  # over the 3 m pillar's top
        (PILLAR_ONLY, (2.0, 5.0, 3.3), (3.5, 5.0, 0.0), False),  # in front of it
        (PILLAR_ONLY, (2.0, 5.0, 3.3), (7.0, 7.0, 0.0), False),  # beside it
        (PILLAR_ONLY, (5.0, 5.0, 8.0), (5.0, 5.0, 3.01), False),  # straight down onto its top
        (SHELF_ONLY, (5.0, 4.0, 3.3), (5.0, 9.0, 0.0), True),  # behind the shelf
        (SHELF_ONLY, (5.0, 4.0, 3.3), (5.0, 9.0, 1.6), False),  # a head above the 1.5 m shelf
        (SHELF_ONLY, (5.0, 4.0, 3.3), (5.0, 6.5, 0.0), False),  # in front of it
        (Obstacles(), (5.0, 4.0, 3.3), (5.0, 9.0, 0.0), False),  # nothing to hit
    ],
)
def test_rays_from_a_camera_are_stopped_by_pillars_and_shelves(obstacles, origin, end, hits: bool) -> None:
    assert obstacles.blocks_rays(np.array(origin), np.array([end]))[0] == hits


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"entries": (Door(5.0, 5.0),)}, "not on the floor border"),
        ({"group_fraction": 1.5}, "group_fraction"),
        ({"standing_fraction": 0.7, "sitting_fraction": 0.5}, "must not exceed 1"),
        ({"identities": None, "people": None}, "needs 'people'"),
        ({"floor": (0.0, 0.0, 0.5, 5.0)}, "room to walk"),
        ({"fps": 0.0}, "fps"),
        ({"goals_per_visit": (3, 2)}, "goals_per_visit"),
        ({"absence_s": (5.0, 1.0)}, "absence_s"),
        ({"identities": -1}, "must not be negative"),
    ],
)
def test_bad_configs_are_refused_with_a_clear_message(changes: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        replace(ROOM, **changes)


def test_goal_areas_covered_by_obstacles_are_reported() -> None:
    area = ((3.8, 3.8), (4.2, 3.8), (4.2, 4.2), (3.8, 4.2))  # inside the pillar
    with pytest.raises(ValueError, match="no free floor"):
        run(replace(ROOM, goal_areas=(GoalArea(area),), frames=1))


def test_an_endless_scene_keeps_going() -> None:
    frames = Scene(replace(ROOM, frames=None, identities=None, people=5)).run()
    for _ in range(700):
        frame = next(frames)
    assert frame.index == 699 and len(frame) == 5
