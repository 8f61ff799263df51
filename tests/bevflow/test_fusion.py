"""Fusion of per-camera cylinders into one row per person."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera
from bevflow.detections import Cylinders
from bevflow.fusion import fuse_cylinders


def ceiling(*positions: tuple[float, float]) -> list[FisheyeCamera]:
    return [FisheyeCamera.looking_down(position=(x, y, 3.3), image_size=(512, 512)) for x, y in positions]


TWO = ceiling((0.0, 0.0), (4.0, 0.0))
THREE = ceiling((0.0, 0.0), (4.0, 0.0), (2.0, 3.0))


@pytest.mark.parametrize(
    "xy, camera, expected_assignment, expected_views",
    [
        # two cameras, one person
        ([[2.0, 0.0], [2.2, 0.1]], [0, 1], [0, 0], [2]),
        # two cameras, two people 0.6 m apart
        ([[2.0, 0.0], [2.6, 0.0]], [0, 1], [0, 1], [1, 1]),
        # exactly the threshold apart is not "closer than"
        ([[2.0, 0.0], [2.45, 0.0]], [0, 1], [0, 1], [1, 1]),
        # one camera, two people close together: never merged
        ([[2.0, 0.0], [2.1, 0.0]], [0, 0], [0, 1], [1, 1]),
        # three cameras, one person
        ([[2.0, 0.5], [2.1, 0.6], [1.9, 0.6]], [0, 1, 2], [0, 0, 0], [3]),
        # a chain A ~ B ~ C with A and C 0.8 m apart: B joins its nearer neighbour C
        ([[1.6, 0.0], [2.0, 0.0], [2.38, 0.0]], [0, 1, 2], [0, 1, 1], [1, 2]),
        # two people of camera 0 both near one cylinder of camera 1: it joins the nearer one
        ([[2.0, 0.0], [2.5, 0.0], [2.3, 0.0]], [0, 0, 1], [0, 1, 1], [1, 2]),
    ],
)
def test_grouping(xy, camera, expected_assignment, expected_views):
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=camera), THREE)
    assert fusion.assignment.tolist() == expected_assignment
    assert fusion.n_views.tolist() == expected_views
    assert len(fusion.fused) == len(expected_views)


def test_single_views_keep_their_camera_and_fused_rows_get_minus_one():
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.1, 0.0], [9.0, 9.0]], camera=[0, 1, 1]), TWO)
    assert fusion.fused.camera.tolist() == [-1, 1]


def test_fused_position_leans_toward_the_closer_camera():
    # Camera 0 stands 0.5 m from the person, camera 1 3.5 m: camera 0's estimate should dominate.
    fusion = fuse_cylinders(Cylinders(xy=[[0.5, 0.0], [0.8, 0.0]], camera=[0, 1]), TWO)
    x = fusion.fused.xy[0, 0]
    assert 0.5 < x < 0.65
    # and with the roles swapped, camera 1's estimate dominates
    fusion = fuse_cylinders(Cylinders(xy=[[3.2, 0.0], [3.5, 0.0]], camera=[0, 1]), TWO)
    assert 3.35 < fusion.fused.xy[0, 0] < 3.5


def test_reliability_weights_are_inverse_square_range_times_score():
    cylinders = Cylinders(xy=[[1.0, 0.0], [1.2, 0.0]], camera=[0, 1], score=[0.5, 0.9], height=[1.6, 1.8])
    w = np.array([0.5 / (1.0**2 + 3.3**2), 0.9 / (2.8**2 + 3.3**2)])
    fused = fuse_cylinders(cylinders, TWO).fused
    assert fused.xy[0] == pytest.approx([(w @ [1.0, 1.2]) / w.sum(), 0.0])
    assert fused.height[0] == pytest.approx((w @ [1.6, 1.8]) / w.sum())
    assert fused.score[0] == pytest.approx(0.9)


@pytest.mark.parametrize("occluded, expected", [([True, True], True), ([True, False], False), ([False, False], False)])
def test_a_person_is_occluded_only_if_every_view_was(occluded, expected):
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.1, 0.0]], camera=[0, 1], occluded=occluded), TWO)
    assert fusion.fused.occluded.tolist() == [expected]


def test_people_are_numbered_in_order_of_arrival():
    fusion = fuse_cylinders(Cylinders(xy=[[9.0, 9.0], [2.0, 0.0], [5.0, 5.0], [2.1, 0.0]], camera=[0, 0, 1, 1]), TWO)
    assert fusion.assignment.tolist() == [0, 1, 2, 1]
    np.testing.assert_allclose(fusion.fused.xy[[0, 2]], [[9.0, 9.0], [5.0, 5.0]])


def test_non_finite_feet_are_dropped():
    fusion = fuse_cylinders(Cylinders(xy=[[np.nan, np.nan], [2.0, 0.0], [2.1, np.inf]], camera=[0, 1, 0]), TWO)
    assert fusion.assignment.tolist() == [-1, 0, -1]
    assert len(fusion.fused) == 1


@pytest.mark.parametrize("xy, camera", [(np.zeros((0, 2)), []), ([[np.nan, 0.0]], [0])])
def test_nothing_to_fuse(xy, camera):
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=camera), TWO)
    assert len(fusion.fused) == 0
    assert fusion.n_views.shape == (0,)
    assert len(fusion.assignment) == len(camera)


@pytest.mark.parametrize(
    "camera, distance_m, message",
    [([2], 0.45, "camera index 2"), ([-1], 0.45, "camera index -1"), ([0], 0.0, "distance_m")],
)
def test_bad_input_is_rejected(camera, distance_m, message):
    with pytest.raises(ValueError, match=message):
        fuse_cylinders(Cylinders(xy=[[0.0, 0.0]], camera=camera), TWO, distance_m=distance_m)


def test_a_hundred_cameras_and_a_crowd():
    rng = np.random.default_rng(4)
    cameras = ceiling(*[(5.0 * i, 5.0 * j) for i in range(10) for j in range(10)])
    centres = np.array([c.center[:2] for c in cameras])
    # people on a 1.2 m lattice with jitter: never two within 0.9 m of each other
    gx, gy = np.meshgrid(np.arange(0.0, 46.0, 1.2), np.arange(0.0, 46.0, 1.2))
    people = np.stack([gx.ravel(), gy.ravel()], axis=1) + rng.uniform(-0.15, 0.15, (gx.size, 2))
    seen_by = np.linalg.norm(people[:, None] - centres[None], axis=2) < 4.0  # each camera's range
    person, camera = np.nonzero(seen_by)
    xy = people[person] + rng.normal(0.0, 0.04, (len(person), 2))  # per-view errors, all pairs < 0.45 m
    order = rng.permutation(len(person))
    fusion = fuse_cylinders(Cylinders(xy=xy[order], camera=camera[order]), cameras)

    assert len(fusion.fused) == len(people)
    # every view of one person lands on one fused row, and no row mixes people
    rows = fusion.assignment
    truth = person[order]
    assert len(set(zip(truth.tolist(), rows.tolist()))) == len(people)
    np.testing.assert_array_equal(np.sort(fusion.n_views), np.sort(seen_by.sum(axis=1)))
    fused_for = np.empty(len(people), dtype=np.int64)
    fused_for[truth] = rows
    assert np.linalg.norm(fusion.fused.xy[fused_for] - people, axis=1).max() < 0.2  # 4σ of one view


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dense_tangled_crowd_keeps_the_rules(seed):
    # People closer than the threshold and noisy views make chains and same-camera conflicts.
    rng = np.random.default_rng(seed)
    cameras = ceiling((0.0, 0.0), (3.0, 0.0), (0.0, 3.0), (3.0, 3.0))
    people = rng.uniform(0.0, 3.0, (60, 2))
    camera = np.repeat(np.arange(4), len(people))
    xy = np.tile(people, (4, 1)) + rng.normal(0.0, 0.15, (4 * len(people), 2))
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=camera), cameras)

    assert fusion.assignment.min() == 0 and fusion.assignment.max() == len(fusion.fused) - 1
    for row in range(len(fusion.fused)):
        members = np.flatnonzero(fusion.assignment == row)
        assert len(set(camera[members].tolist())) == len(members) == fusion.n_views[row]
        gaps = np.linalg.norm(xy[members, None] - xy[None, members], axis=2)
        assert gaps.max() < 0.45
    # and pairs that could have joined mostly did: far fewer rows than cylinders
    assert len(fusion.fused) < 0.75 * len(xy)
