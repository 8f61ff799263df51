"""Fusion of per-camera cylinders into one row per person: position uncertainty, gating, grouping,
the fused position and weak views; ceiling fisheyes (the paper's case) and side-view pinholes."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bevflow.camera import FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.detections import Cylinders
from bevflow.fusion import (
    CROSSED_CUT_VIEWS_SCORE,
    PositionNoise,
    _components,
    fuse_cylinders,
    position_covariance,
    with_position_covariance,
)
from bevflow.tracking.tracker import TrackerConfig

PAPER = {"noise": None}  # the paper's rule: feet closer than 0.45 m
DEFAULT: dict = {}


def ceiling(*positions: tuple[float, float]) -> list[FisheyeCamera]:
    return [FisheyeCamera.looking_down(position=(x, y, 3.3), image_size=(512, 512)) for x, y in positions]


def side_view(position: tuple[float, float, float], yaw_deg: float) -> PinholeCamera:
    """A WILDTRACK-like camera looking 20 degrees below level; yaw 0 looks along +Y, 90 along -X."""
    R = rotation_from_ypr(yaw_deg, 70.0, 0.0)
    K = np.array([[1700.0, 0.0, 960.0], [0.0, 1700.0, 540.0], [0.0, 0.0, 1.0]])
    return PinholeCamera(K=K, dist=np.zeros(5), R=R, t=-R @ np.asarray(position, dtype=float), image_size=(1920, 1080))


TWO = ceiling((0.0, 0.0), (4.0, 0.0))
THREE = ceiling((0.0, 0.0), (4.0, 0.0), (2.0, 3.0))
# Two side views of the point (0, 10) at right angles: camera 0 looks along +Y, camera 1 along -X.
CROSSED = [side_view((0.0, 0.0, 2.5), 0.0), side_view((10.0, 10.0, 2.5), 90.0)]


# --- position covariance ----------------------------------------------------------------------------
def test_without_box_noise_the_covariance_is_the_floor_term_alone():
    cylinders = Cylinders(xy=[[0.0, 10.0], [1.0, 0.5]], camera=[0, 1])
    cov = position_covariance(cylinders, [CROSSED[0], TWO[0]], PositionNoise(box_fraction=0.0, floor_m=0.2))
    np.testing.assert_allclose(cov, np.broadcast_to(0.04 * np.eye(2), (2, 2, 2)))


def test_a_side_view_is_uncertain_along_its_line_of_sight_and_more_so_with_range():
    noise = PositionNoise(floor_m=1e-9)
    cov = position_covariance(Cylinders(xy=[[0.0, 5.0], [0.0, 10.0], [0.0, 20.0]], camera=[0, 0, 0]), CROSSED, noise)
    values, vectors = np.linalg.eigh(cov)
    along, across = np.sqrt(values[:, 1]), np.sqrt(values[:, 0])
    np.testing.assert_allclose(np.abs(vectors[:, :, 1]), np.broadcast_to([0.0, 1.0], (3, 2)), atol=1e-3)  # along +Y
    assert (along > 5 * across).all()
    # The floor step per pixel grows with range², the person's pixel size falls as 1 / range.
    assert along[1] / along[0] == pytest.approx(2.0, rel=0.2)
    assert along[2] / along[1] == pytest.approx(2.0, rel=0.2)


@pytest.mark.parametrize("camera, xy", [(CROSSED[0], (1.0, 12.0)), (TWO[0], (2.2, 0.7))], ids=["side view", "fisheye"])
def test_covariance_matches_box_errors_carried_to_the_floor_by_sampling(camera, xy):
    # Independent of the Jacobian: jitter the feet pixel by the box's size, back-project each
    # sample with pixels_to_plane, and compare the sample covariance.
    noise = PositionNoise(box_fraction=0.03, floor_m=1e-9)
    cylinder = Cylinders(xy=[xy], camera=[0], height=[1.7], radius=[0.3])
    corners = [(xy[0] + sx * 0.3, xy[1] + sy * 0.3, z) for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, 1.7)]
    uv = camera.project(np.array(corners))
    sigma = 0.03 * (uv.max(axis=0) - uv.min(axis=0))
    feet = camera.project(np.array([[xy[0], xy[1], 0.0]]))
    rng = np.random.default_rng(0)
    samples = camera.pixels_to_plane(feet + rng.normal(0.0, 1.0, (20000, 2)) * sigma, 0.0)[:, :2]
    expected = np.cov(samples.T)
    got = position_covariance(cylinder, [camera], noise)[0]
    np.testing.assert_allclose(got, expected, rtol=0.1, atol=0.05 * np.abs(expected).max())


def test_feet_rebuilt_from_the_head_add_the_height_error_along_the_line_of_sight():
    # Camera at (0, 0, 3.3), head plane 1.7 m: 2 m out the head's ray drops 1.6 m, so 0.1 m of
    # height error moves the feet 0.125 m along x.
    noise = PositionNoise(box_fraction=0.0, floor_m=0.05, head_height_m=0.1)
    cov = position_covariance(Cylinders(xy=[[2.0, 0.0]], camera=[0], height=[1.7], occluded=[True]), TWO, noise)[0]
    np.testing.assert_allclose(cov, [[0.05**2 + 0.125**2, 0.0], [0.0, 0.05**2]], atol=1e-12)


def test_feet_the_camera_cannot_see_fall_back_to_the_floor_term():
    behind = Cylinders(xy=[[0.0, -10.0]], camera=[0])  # behind the side view: nothing projects
    cov = position_covariance(behind, CROSSED, PositionNoise(floor_m=0.3))
    np.testing.assert_allclose(cov[0], 0.09 * np.eye(2))


def test_covariance_needs_per_camera_cylinders():
    with pytest.raises(ValueError, match="camera index -1"):
        position_covariance(Cylinders(xy=[[0.0, 0.0]], camera=[-1]), TWO)


def test_covariance_is_exactly_symmetric_and_carried_by_with_position_covariance():
    seen = Cylinders(xy=[[0.3, 9.0], [2.2, 0.7], [1.4, -0.9]], camera=[0, 1, 1], occluded=[False, True, False])
    cameras = [CROSSED[0], TWO[0]]
    cov = position_covariance(seen, cameras)
    np.testing.assert_array_equal(cov, cov.transpose(0, 2, 1))
    assert (cov[:, 0, 1] != 0).any()  # not symmetric by being diagonal
    carried = with_position_covariance(seen, cameras)
    np.testing.assert_array_equal(carried.covariance, cov)
    np.testing.assert_array_equal(carried.xy, seen.xy)


# --- covariances carried by the cylinders ----------------------------------------------------------------
def test_carried_covariances_are_used_instead_of_the_geometry():
    # 0.8 m apart: too far for the fisheyes' own covariances, but within the gate of wide ones.
    seen = Cylinders(xy=[[2.0, 0.0], [2.8, 0.0]], camera=[0, 1])
    assert fuse_cylinders(seen, TWO).n_views.tolist() == [1, 1]
    wide = replace(seen, covariance=np.broadcast_to(np.eye(2), (2, 2, 2)))
    assert fuse_cylinders(wide, TWO).n_views.tolist() == [2]
    assert fuse_cylinders(wide, TWO, noise=None).n_views.tolist() == [1, 1]  # the paper's rule ignores them


@pytest.mark.parametrize("known", [[True, True, True, True], [True, False, True, False], [False] * 4])
def test_rows_without_a_carried_covariance_get_the_computed_one(known):
    rng = np.random.default_rng(3)
    seen = Cylinders(xy=rng.uniform(1.0, 3.0, (4, 2)), camera=[0, 1, 2, 1], occluded=[False, True, False, False])
    carried = with_position_covariance(seen, THREE).covariance.copy()
    carried[~np.asarray(known)] = np.nan
    expected = fuse_cylinders(seen, THREE)
    got = fuse_cylinders(replace(seen, covariance=carried), THREE)
    np.testing.assert_array_equal(got.assignment, expected.assignment)
    np.testing.assert_array_equal(got.fused.xy, expected.fused.xy)


@pytest.mark.parametrize(
    "settings",
    [{"box_fraction": -0.1}, {"floor_m": 0.0}, {"head_height_m": -1.0}, {"floor_m": math.nan}, {"weak_along_m": -1.0}],
)
def test_position_noise_rejects_bad_settings(settings):
    with pytest.raises(ValueError, match="PositionNoise"):
        PositionNoise(**settings)


# --- grouping ---------------------------------------------------------------------------------------
BOTH = [pytest.param(PAPER, id="paper"), pytest.param(DEFAULT, id="default")]


@pytest.mark.parametrize("mode", BOTH)
@pytest.mark.parametrize(
    "xy, camera, expected_assignment, expected_views",
    [
        # two cameras, one person
        ([[2.0, 0.0], [2.2, 0.1]], [0, 1], [0, 0], [2]),
        # two cameras, two people 0.7 m apart
        ([[2.0, 0.0], [2.7, 0.0]], [0, 1], [0, 1], [1, 1]),
        # one camera, two people close together: never merged
        ([[2.0, 0.0], [2.1, 0.0]], [0, 0], [0, 1], [1, 1]),
        # three cameras, one person
        ([[2.0, 0.5], [2.1, 0.6], [1.9, 0.6]], [0, 1, 2], [0, 0, 0], [3]),
        # two people of camera 0 both near one cylinder of camera 1: it joins the nearer one
        ([[2.0, 0.0], [2.5, 0.0], [2.3, 0.0]], [0, 0, 1], [0, 1, 1], [1, 2]),
    ],
)
def test_grouping_under_ceiling_cameras(mode, xy, camera, expected_assignment, expected_views):
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=camera), THREE, **mode)
    assert fusion.assignment.tolist() == expected_assignment
    assert fusion.n_views.tolist() == expected_views
    assert len(fusion.fused) == len(expected_views)


@pytest.mark.parametrize("mode, expected_assignment", [(PAPER, [0, 1, 1]), (DEFAULT, [0, 0, 1])])
def test_a_chain_is_cut_where_the_estimates_agree_least(mode, expected_assignment):
    # A ~ B ~ C with A and C 0.78 m apart. By distance B is nearer C (0.38 m against 0.40 m). But A
    # and B come from cameras on the x axis, whose estimates are uncertain along x, and C from the
    # camera at (2, 3), uncertain along y: A and B disagree where they are unsure, B and C do not.
    seen = Cylinders(xy=[[1.6, 0.0], [2.0, 0.0], [2.38, 0.0]], camera=[0, 1, 2])
    assert fuse_cylinders(seen, THREE, **mode).assignment.tolist() == expected_assignment


@pytest.mark.parametrize("mode, expected_views", [(PAPER, [1, 1]), (DEFAULT, [2])])
def test_exactly_the_distance_apart_is_not_closer_than_but_may_agree_within_the_uncertainty(mode, expected_views):
    # 0.45 m between two ceiling estimates whose sigmas are about 0.12 m each: d² ≈ 7 < 9.21.
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.45, 0.0]], camera=[0, 1]), TWO, **mode)
    assert fusion.n_views.tolist() == expected_views


@pytest.mark.parametrize("distance_m", [0.45, 1.0])
def test_the_distance_rule_always_merges_even_when_the_covariances_are_tight(distance_m):
    noise = PositionNoise(box_fraction=0.0, floor_m=0.01)  # d² = (0.4 / 0.014)² = 800
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.4, 0.0]], camera=[0, 1]), TWO, distance_m, noise=noise)
    assert fusion.n_views.tolist() == [2]


def test_side_views_merge_estimates_that_disagree_along_their_lines_of_sight():
    # Each camera puts the person at (0, 10) 0.5 m too far along its own line of sight: 0.71 m
    # apart, too far for the paper's rule, but each lies along the other's long axis.
    seen = Cylinders(xy=[[0.0, 10.5], [-0.5, 10.0]], camera=[0, 1])
    assert fuse_cylinders(seen, CROSSED, **PAPER).n_views.tolist() == [1, 1]
    fusion = fuse_cylinders(seen, CROSSED)
    assert fusion.n_views.tolist() == [2]
    # The fused feet follow each camera across its line of sight, where it is precise: near the
    # truth, unlike the plain mean (0.35 m off each way).
    truth = np.array([0.0, 10.0])
    assert np.linalg.norm(fusion.fused.xy[0] - truth) < 0.15
    assert np.linalg.norm(fusion.fused.xy[0] - truth) < 0.5 * np.linalg.norm(seen.xy.mean(axis=0) - truth)


@pytest.mark.parametrize("offset, expected_views", [((0.0, 0.7), [2]), ((0.5, 0.0), [1, 1])], ids=["along", "across"])
def test_side_views_looking_the_same_way_merge_along_their_lines_of_sight_only(offset, expected_views):
    # Two cameras 3 m apart, both looking along +Y at a person 10 m ahead.
    cameras = [side_view((0.0, 0.0, 2.5), 0.0), side_view((3.0, 0.0, 2.5), 0.0)]
    seen = Cylinders(xy=[[0.0, 10.0], [offset[0], 10.0 + offset[1]]], camera=[0, 1])
    assert fuse_cylinders(seen, cameras).n_views.tolist() == expected_views


@pytest.mark.parametrize("max_gate_m, expected_views", [(2.0, [2]), (0.6, [1, 1])])
def test_no_pair_merges_beyond_the_largest_gate(max_gate_m, expected_views):
    noise = PositionNoise(box_fraction=0.0, floor_m=1.0)  # everything agrees within the uncertainty
    seen = Cylinders(xy=[[0.0, 10.0], [0.8, 10.0]], camera=[0, 1])
    assert fuse_cylinders(seen, CROSSED, noise=noise, max_gate_m=max_gate_m).n_views.tolist() == expected_views


# --- the fused row ------------------------------------------------------------------------------------
def test_single_views_keep_their_camera_and_fused_rows_get_minus_one():
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.1, 0.0], [9.0, 9.0]], camera=[0, 1, 1]), TWO)
    assert fusion.fused.camera.tolist() == [-1, 1]


@pytest.mark.parametrize("mode", BOTH)
def test_fused_position_leans_toward_the_closer_camera(mode):
    # Camera 0 stands 0.5 m from the person, camera 1 3.5 m: camera 0's estimate should dominate.
    fusion = fuse_cylinders(Cylinders(xy=[[0.5, 0.0], [0.8, 0.0]], camera=[0, 1]), TWO, **mode)
    assert 0.5 < fusion.fused.xy[0, 0] < 0.65
    # and with the roles swapped, camera 1's estimate dominates
    fusion = fuse_cylinders(Cylinders(xy=[[3.2, 0.0], [3.5, 0.0]], camera=[0, 1]), TWO, **mode)
    assert 3.35 < fusion.fused.xy[0, 0] < 3.5


def test_paper_weights_are_inverse_square_range_times_score():
    cylinders = Cylinders(xy=[[1.0, 0.0], [1.2, 0.0]], camera=[0, 1], score=[0.5, 0.9], height=[1.6, 1.8])
    w = np.array([0.5 / (1.0**2 + 3.3**2), 0.9 / (2.8**2 + 3.3**2)])
    fused = fuse_cylinders(cylinders, TWO, **PAPER).fused
    assert fused.xy[0] == pytest.approx([(w @ [1.0, 1.2]) / w.sum(), 0.0])
    assert fused.height[0] == pytest.approx((w @ [1.6, 1.8]) / w.sum())
    assert fused.score[0] == pytest.approx(0.9)


def test_default_weights_are_the_inverse_covariances():
    cylinders = Cylinders(xy=[[0.0, 10.3], [-0.2, 10.1]], camera=[0, 1], height=[1.6, 1.8], score=[0.5, 0.9])
    cov = position_covariance(cylinders, CROSSED)
    info = np.linalg.inv(cov)
    expected = np.linalg.solve(info.sum(axis=0), np.einsum("nij,nj->i", info, cylinders.xy))
    w = 1.0 / np.sqrt(np.linalg.det(cov))
    fused = fuse_cylinders(cylinders, CROSSED).fused
    np.testing.assert_allclose(fused.xy[0], expected)
    assert fused.height[0] == pytest.approx((w @ [1.6, 1.8]) / w.sum())
    assert fused.score[0] == pytest.approx(0.9)  # the best view's


def test_fused_people_carry_the_covariance_of_their_information_weighted_feet():
    cylinders = Cylinders(xy=[[0.0, 10.3], [-0.2, 10.1], [5.0, 5.0]], camera=[0, 1, 0])
    cov = position_covariance(cylinders, CROSSED)
    fusion = fuse_cylinders(cylinders, CROSSED)
    assert fusion.n_views.tolist() == [2, 1]
    np.testing.assert_allclose(fusion.fused.covariance[0], np.linalg.inv(np.linalg.inv(cov[:2]).sum(axis=0)))
    np.testing.assert_allclose(fusion.fused.covariance[1], cov[2])
    # two crossed side views pin the feet down better than either alone, in every direction
    assert np.all(np.linalg.eigvalsh(cov[:2] - fusion.fused.covariance[0]) > 0)
    assert fuse_cylinders(cylinders, CROSSED, **PAPER).fused.covariance is None


@pytest.mark.parametrize("occluded, expected", [([True, True], True), ([True, False], False), ([False, False], False)])
def test_a_person_is_occluded_only_if_every_view_was(occluded, expected):
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.1, 0.0]], camera=[0, 1], occluded=occluded), TWO)
    assert fusion.fused.occluded.tolist() == [expected]


@pytest.mark.parametrize(
    "stature, expected",
    [([1.60, 1.70], 1.65), ([np.nan, 1.70], 1.70), ([np.nan, np.nan], np.nan)],
    ids=["both measured", "one measured", "neither"],
)
def test_a_persons_head_height_is_the_mean_of_their_views_that_measured_it(stature, expected):
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.1, 0.0]], camera=[0, 1], stature=stature), TWO)
    np.testing.assert_allclose(fusion.fused.stature, [expected])


def test_people_are_numbered_in_order_of_arrival():
    fusion = fuse_cylinders(Cylinders(xy=[[9.0, 9.0], [2.0, 0.0], [5.0, 5.0], [2.1, 0.0]], camera=[0, 0, 1, 1]), TWO)
    assert fusion.assignment.tolist() == [0, 1, 2, 1]
    np.testing.assert_allclose(fusion.fused.xy[[0, 2]], [[9.0, 9.0], [5.0, 5.0]])


# --- weak views ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", BOTH)
def test_a_weak_view_confirms_a_person_but_does_not_move_them(mode):
    fusion = fuse_cylinders(Cylinders(xy=[[2.0, 0.0], [2.2, 0.1]], camera=[0, 1], score=[0.8, 0.0]), TWO, **mode)
    assert fusion.assignment.tolist() == [0, 0] and fusion.n_views.tolist() == [2]
    np.testing.assert_allclose(fusion.fused.xy, [[2.0, 0.0]], atol=1e-12)
    assert fusion.fused.score.tolist() == [0.8]


@pytest.mark.parametrize("mode", BOTH)
def test_weak_views_alone_are_no_one(mode):
    # (6.0, 0) and (6.1, 0): both cameras see them looking along +X, so they do not cross
    xy = [[9.0, 9.0], [6.0, 0.0], [6.1, 0.0], [5.0, 5.0]]
    seen = Cylinders(xy=xy, camera=[0, 0, 1, 1], score=[0.0, 0.0, 0.0, 0.7])
    fusion = fuse_cylinders(seen, TWO, **mode)
    assert fusion.assignment.tolist() == [-1, -1, -1, 0]
    np.testing.assert_allclose(fusion.fused.xy, [[5.0, 5.0]])
    assert fusion.n_views.tolist() == [1]
    np.testing.assert_allclose(fusion.sightings.xy, xy[:3])  # they are kept as sightings
    assert fusion.sightings.camera.tolist() == [0, 0, 1]


def test_a_sighting_is_uncertain_along_its_line_of_sight_only():
    # Camera 0 of CROSSED stands at the origin and sees (0, 10) along +Y; a confirmed view of
    # camera 1 elsewhere keeps the scene from being weak views alone.
    seen = Cylinders(xy=[[0.0, 10.0], [8.0, 3.0]], camera=[0, 1], score=[0.0, 0.9])
    noise = PositionNoise(weak_along_m=2.0)
    sighting = fuse_cylinders(seen, CROSSED, noise=noise).sightings
    fit = position_covariance(seen[:1], CROSSED, noise)[0]
    np.testing.assert_allclose(sighting.covariance[0], fit + np.diag([0.0, 4.0]), atol=1e-12)
    assert len(fuse_cylinders(seen[1:], CROSSED).sightings) == 0


# --- cut views that cross ---------------------------------------------------------------------------
# CROSSED's cameras see (0, 10) at right angles; SAME_WAY's two both look along +Y, 16° apart there.
SAME_WAY = [side_view((0.0, 0.0, 2.5), 0.0), side_view((3.0, 0.0, 2.5), 0.0)]


@pytest.mark.parametrize(
    "cameras, xy, options, person",
    [
        (CROSSED, [[0.0, 10.0], [0.1, 10.1]], {}, True),
        (CROSSED, [[0.0, 10.0], [0.1, 10.1]], {"crossing_deg": 80.0}, True),
        (CROSSED, [[0.0, 10.0], [0.1, 10.1]], {"crossing_deg": 100.0}, False),  # 90° is not enough
        (CROSSED, [[0.0, 10.0], [0.1, 10.1]], {"crossing_deg": math.inf}, False),
        (CROSSED, [[0.0, 10.0], [0.1, 10.1]], PAPER, False),
        (CROSSED, [[0.0, 10.5], [0.0, 10.0]], {}, False),  # one group under the gate, 0.5 m apart
        (SAME_WAY, [[0.0, 10.0], [0.1, 10.0]], {}, False),  # both too far the same way: no proof
    ],
    ids=["crossed", "80 degrees", "100 degrees", "off", "paper", "too far apart", "same way"],
)
def test_cut_views_whose_lines_of_sight_cross_place_a_person(cameras, xy, options, person):
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=[0, 1], score=[0.0, 0.0]), cameras, **options)
    assert fusion.assignment.tolist() == ([0, 0] if person else [-1, -1])
    assert len(fusion.sightings) == (0 if person else 2)
    if person:
        np.testing.assert_allclose(fusion.fused.xy[0], [0.05, 10.05], atol=0.1)
        # strong enough for the tracker to start a track from them
        assert fusion.fused.score.tolist() == [CROSSED_CUT_VIEWS_SCORE]
        assert CROSSED_CUT_VIEWS_SCORE >= TrackerConfig().weak_score


def test_a_strong_view_keeps_its_score_beside_cut_views_that_cross():
    seen = Cylinders(xy=[[0.0, 10.0], [0.1, 10.1], [0.05, 9.95]], camera=[0, 1, 2], score=[0.0, 0.0, 0.9])
    fusion = fuse_cylinders(seen, [*CROSSED, side_view((-4.0, 10.0, 2.5), -90.0)])
    assert fusion.assignment.tolist() == [0, 0, 0] and fusion.fused.score.tolist() == [0.9]


def test_crossing_needs_a_positive_angle():
    with pytest.raises(ValueError, match="crossing_deg"):
        fuse_cylinders(Cylinders.empty(), CROSSED, crossing_deg=0.0)


# --- hidden views the occlusion test missed ---------------------------------------------------------
# A person at (0, 10) seen by both CROSSED cameras, and a third side view looking along +X at
# them from 14 m (FAR: rays shallower than 4 m of run per metre of its 2.5 m height) or from 4 m.
FAR = [*CROSSED, side_view((-14.0, 10.0, 2.5), -90.0)]
NEAR = [*CROSSED, side_view((-4.0, 10.0, 2.5), -90.0)]
PERSON = ([[0.05, 10.0], [0.0, 10.05]], [0, 1])


@pytest.mark.parametrize(
    "cameras, xy, camera, options, folded",
    [
        (FAR, [[3.0, 10.0]], [2], {}, True),  # 3 m behind them on camera 2's line of sight
        (FAR, [[3.0, 11.5]], [2], {}, False),  # 1.5 m off that line: someone else
        (FAR, [[-3.0, 10.0]], [2], {}, False),  # in front of them: it could not be their cut box
        (FAR, [[-0.05, 10.0], [3.0, 10.0]], [2, 2], {}, False),  # camera 2 boxed them whole: two people
        (NEAR, [[3.0, 10.0]], [2], {}, False),  # a steep view: the occlusion tests do not miss there
        (FAR, [[3.0, 10.0]], [2], {"hidden_view_slope": math.inf}, False),
        (FAR, [[3.0, 10.0]], [2], PAPER, False),
    ],
    ids=["behind", "beside", "in front", "seen whole", "steep", "off", "paper"],
)
def test_a_single_view_behind_a_person_its_camera_did_not_box_is_folded_into_them(cameras, xy, camera, options, folded):
    seen = Cylinders(xy=PERSON[0] + xy, camera=PERSON[1] + camera)
    fusion = fuse_cylinders(seen, cameras, **options)
    last = fusion.assignment[-1]
    if folded:
        assert fusion.assignment.tolist() == [0, 0, 0] and fusion.n_views.tolist() == [3]
        np.testing.assert_allclose(fusion.fused.xy, fuse_cylinders(seen[:2], cameras).fused.xy)  # not moved
    else:
        assert last != fusion.assignment[0] and fusion.n_views[last] == 1
        np.testing.assert_allclose(fusion.fused.xy[last], xy[-1])


def test_a_single_view_is_not_folded_into_a_person_of_one_view():
    seen = Cylinders(xy=[[0.05, 10.0], [3.0, 10.0]], camera=[0, 2])
    assert fuse_cylinders(seen, FAR).n_views.tolist() == [1, 1]


# --- grouping ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("n, edges, seed", [(1, 0, 0), (10, 0, 1), (10, 30, 2), (200, 150, 3), (200, 600, 4), (50, 20, 5)])
def test_components_match_scipy(n: int, edges: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    a, b = rng.integers(0, n, edges), rng.integers(0, n, edges)
    labels = _components(n, a, b)
    _, reference = connected_components(coo_matrix((np.ones(edges), (a, b)), shape=(n, n)), directed=False)
    # The same partition, each row labelled with the smallest row of its component.
    assert (labels[:, None] == labels[None, :]).tolist() == (reference[:, None] == reference[None, :]).tolist()
    assert all(labels[r] == np.flatnonzero(labels == labels[r]).min() for r in range(n))


def test_a_long_chain_is_one_component() -> None:
    n = 1000
    labels = _components(n, np.arange(n - 1)[::-1], np.arange(1, n)[::-1])
    assert (labels == 0).all()


# --- edges ----------------------------------------------------------------------------------------------
def test_non_finite_feet_are_dropped():
    fusion = fuse_cylinders(Cylinders(xy=[[np.nan, np.nan], [2.0, 0.0], [2.1, np.inf]], camera=[0, 1, 0]), TWO)
    assert fusion.assignment.tolist() == [-1, 0, -1]
    assert len(fusion.fused) == 1


@pytest.mark.parametrize("mode", BOTH)
@pytest.mark.parametrize("xy, camera", [(np.zeros((0, 2)), []), ([[np.nan, 0.0]], [0])])
def test_nothing_to_fuse(mode, xy, camera):
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=camera), TWO, **mode)
    assert len(fusion.fused) == 0
    assert fusion.n_views.shape == (0,)
    assert len(fusion.assignment) == len(camera)


@pytest.mark.parametrize(
    "camera, options, message",
    [
        ([2], {}, "camera index 2"),
        ([-1], {}, "camera index -1"),
        ([0], {"distance_m": 0.0}, "distance_m"),
        ([0], {"gate_chi2": -1.0}, "gate_chi2"),
        ([0], {"max_gate_m": 0.0}, "max_gate_m"),
    ],
)
def test_bad_input_is_rejected(camera, options, message):
    with pytest.raises(ValueError, match=message):
        fuse_cylinders(Cylinders(xy=[[0.0, 0.0]], camera=camera), TWO, **options)


# --- scale and crowds -----------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", BOTH)
def test_a_hundred_cameras_and_a_crowd(mode):
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
    fusion = fuse_cylinders(Cylinders(xy=xy[order], camera=camera[order]), cameras, **mode)

    assert len(fusion.fused) == len(people)
    # every view of one person lands on one fused row, and no row mixes people
    rows = fusion.assignment
    truth = person[order]
    assert len(set(zip(truth.tolist(), rows.tolist(), strict=True))) == len(people)
    np.testing.assert_array_equal(np.sort(fusion.n_views), np.sort(seen_by.sum(axis=1)))
    fused_for = np.empty(len(people), dtype=np.int64)
    fused_for[truth] = rows
    assert np.linalg.norm(fusion.fused.xy[fused_for] - people, axis=1).max() < 0.2  # 4σ of one view


@pytest.mark.parametrize("mode", BOTH)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dense_tangled_crowd_keeps_the_rules(mode, seed):
    # People closer than the gates and noisy views make chains and same-camera conflicts.
    rng = np.random.default_rng(seed)
    cameras = ceiling((0.0, 0.0), (3.0, 0.0), (0.0, 3.0), (3.0, 3.0))
    people = rng.uniform(0.0, 3.0, (60, 2))
    camera = np.repeat(np.arange(4), len(people))
    xy = np.tile(people, (4, 1)) + rng.normal(0.0, 0.15, (4 * len(people), 2))
    seen = Cylinders(xy=xy, camera=camera)
    fusion = fuse_cylinders(seen, cameras, **mode)
    cov = position_covariance(seen, cameras)

    assert fusion.assignment.min() == 0 and fusion.assignment.max() == len(fusion.fused) - 1
    for row in range(len(fusion.fused)):
        members = np.flatnonzero(fusion.assignment == row)
        assert len(set(camera[members].tolist())) == len(members) == fusion.n_views[row]
        for i in members:  # every pair linked: closer than 0.45 m, or (default) within the χ² gate
            for j in members[members > i]:
                d = xy[i] - xy[j]
                linked = np.linalg.norm(d) < 0.45
                if mode is DEFAULT:
                    linked |= float(d @ np.linalg.solve(cov[i] + cov[j], d)) < 9.21
                assert linked
    # and pairs that could have joined mostly did: far fewer rows than cylinders
    assert len(fusion.fused) < 0.75 * len(xy)


def greedy_cliques(xy, camera, cov, distance_m=0.45, gate_chi2=9.21, max_gate_m=2.0):
    """The grouping rule written out over all pairs: join groups along linked pairs of distinct
    cameras, surest pair first, when every cross pair is linked. A set of frozensets of rows."""
    n = len(xy)
    d = xy[:, None] - xy[None]
    gap = np.linalg.norm(d, axis=2)
    d2 = np.einsum("abi,abij,abj->ab", d, np.linalg.inv(cov[:, None] + cov[None]), d)
    depth = np.minimum((gap / distance_m) ** 2, np.where(gap < max_gate_m, d2 / gate_chi2, np.inf))
    linked = (depth < 1.0) & (camera[:, None] != camera[None])
    group = list(range(n))
    members = {k: {k} for k in range(n)}
    i, j = np.nonzero(np.triu(linked, 1))
    for a, b in sorted(zip(i.tolist(), j.tolist(), strict=True), key=lambda p: depth[p]):
        ga, gb = group[a], group[b]
        if ga == gb or {camera[k] for k in members[ga]} & {camera[k] for k in members[gb]}:
            continue
        if all(linked[p, q] for p in members[ga] for q in members[gb]):
            members[ga] |= members.pop(gb)
            for k in members[ga]:
                group[k] = ga
    return {frozenset(m) for m in members.values()}


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_grouping_follows_the_greedy_rule_pair_by_pair(seed):
    rng = np.random.default_rng(seed)
    cameras = ceiling((0.0, 0.0), (3.0, 0.0), (0.0, 3.0), (3.0, 3.0))
    people = rng.uniform(0.0, 3.0, (40, 2))
    camera = np.repeat(np.arange(4), len(people))
    seen = Cylinders(xy=np.tile(people, (4, 1)) + rng.normal(0.0, 0.15, (4 * len(people), 2)), camera=camera)
    assignment = fuse_cylinders(seen, cameras).assignment
    groups = {frozenset(np.flatnonzero(assignment == row).tolist()) for row in range(assignment.max() + 1)}
    assert groups == greedy_cliques(seen.xy, camera, position_covariance(seen, cameras))


# --- tracks as priors -------------------------------------------------------------------------------
def _priors(*xy: tuple[float, float], sigma_m: float = 0.1) -> Cylinders:
    return Cylinders(xy=list(xy), covariance=np.tile(sigma_m**2 * np.eye(2), (len(xy), 1, 1)))


@pytest.mark.parametrize(
    "xy, camera, score, priors, expected_assignment, expected_views",
    [
        # two views 0.6 m apart, too far to merge alone, both near one prior: one person
        ([[2.0, 0.0], [2.6, 0.0]], [0, 1], [1.0, 1.0], _priors((2.3, 0.0), sigma_m=0.25), [0, 0], [2]),
        # the same views without a prior: two people
        ([[2.0, 0.0], [2.6, 0.0]], [0, 1], [1.0, 1.0], None, [0, 1], [1, 1]),
        # one camera's two views near one prior: the nearer one joins it, the other is someone else
        ([[2.0, 0.0], [2.3, 0.0]], [0, 0], [1.0, 1.0], _priors((2.05, 0.0)), [0, 1], [1, 1]),
        # a weak view alone is nobody, but where a prior expects someone it places them
        ([[2.0, 0.0]], [0], [0.0], None, [-1], []),
        ([[2.0, 0.0]], [0], [0.0], _priors((2.05, 0.0)), [0], [1]),
        # a prior with no view near it makes no one
        ([[2.0, 0.0]], [0], [1.0], _priors((5.0, 2.0)), [0], [1]),
    ],
    ids=["views of one prior", "no prior", "one view per camera", "weak alone", "weak on a prior", "prior far away"],
)
def test_priors_group_the_views_of_the_people_expected(xy, camera, score, priors, expected_assignment, expected_views):
    fusion = fuse_cylinders(Cylinders(xy=xy, camera=camera, score=score), THREE, priors=priors)
    assert fusion.assignment.tolist() == expected_assignment
    assert fusion.n_views.tolist() == expected_views


def test_a_weak_view_on_a_prior_moves_the_person_and_is_not_a_sighting():
    seen = Cylinders(xy=[[6.0, 0.0], [6.2, 0.0]], camera=[0, 1], score=[0.0, 0.0])  # seen the same way
    fusion = fuse_cylinders(seen, THREE, priors=_priors((6.1, 0.0)))
    assert len(fusion.sightings) == 0
    np.testing.assert_allclose(fusion.fused.xy, [[6.1, 0.0]], atol=0.05)
    assert fusion.fused.score.tolist() == [0.0]  # still weak: the tracker only continues tracks with it


def test_priors_with_nothing_seen_make_no_one():
    fusion = fuse_cylinders(Cylinders.empty(), THREE, priors=_priors((2.0, 0.0)))
    assert (len(fusion.fused), fusion.assignment.tolist()) == (0, [])
