from __future__ import annotations

import math

import numpy as np
import pytest

from bevflow.sim.bodies import LOWER_PARTS, PART_INDEX, PART_NAMES, BodyShape, Posture, pose_bodies


def pose(
    n: int = 1,
    height: float = 1.75,
    xy: tuple[float, float] = (0.0, 0.0),
    heading: float = 0.0,
    phase: float = 0.0,
    speed: float = 0.0,
    posture: Posture = Posture.STANDING,
):
    return pose_bodies(
        BodyShape.standard(n, height),
        np.tile(xy, (n, 1)),
        np.full(n, heading),
        np.full(n, phase),
        np.full(n, speed),
        np.full(n, int(posture)),
    )


def top_of(prims) -> np.ndarray:
    """Highest point of each body: max over ellipsoids of centre z + vertical half-extent."""
    vertical_extent = np.linalg.norm(prims.axes[..., 2, :] * prims.radii, axis=-1)
    return (prims.centers[..., 2] + vertical_extent).max(axis=1)


@pytest.mark.parametrize("height", [1.5, 1.72, 1.95])
def test_standing_body_is_as_tall_as_its_stature_and_stands_on_the_floor(height: float) -> None:
    prims = pose(height=height)
    assert top_of(prims)[0] == pytest.approx(height, abs=0.005)
    vertical_extent = np.linalg.norm(prims.axes[..., 2, :] * prims.radii, axis=-1)
    assert (prims.centers[..., 2] - vertical_extent).min() == pytest.approx(0.0, abs=0.01)


def test_sitting_lowers_the_body_and_puts_the_knees_forward() -> None:
    standing, sitting = pose(posture=Posture.STANDING), pose(posture=Posture.SITTING)
    # The pelvis drops by about a thigh length (24.5 % of stature).
    assert top_of(standing)[0] - top_of(sitting)[0] == pytest.approx(0.245 * 1.75, abs=0.02)
    thighs = [PART_INDEX["thigh_left"], PART_INDEX["thigh_right"]]
    assert np.all(sitting.centers[0, thighs, 0] > 0.15)  # forward along heading +X
    assert np.allclose(standing.centers[0, thighs, 0], 0.0, atol=1e-9)


def test_walking_swings_the_legs_against_the_arms_and_standing_does_not() -> None:
    foot_l, foot_r = PART_INDEX["foot_left"], PART_INDEX["foot_right"]
    arm_l = PART_INDEX["forearm_left"]
    walk = pose(phase=math.pi / 2, speed=1.3, posture=Posture.WALKING)
    stride = walk.centers[0, foot_l, 0] - walk.centers[0, foot_r, 0]
    assert 0.4 < stride < 0.9  # a normal step at 1.3 m/s
    assert walk.centers[0, arm_l, 0] < walk.centers[0, PART_INDEX["forearm_right"], 0]
    still = pose(phase=math.pi / 2, speed=1.3, posture=Posture.STANDING)
    assert still.centers[0, foot_l, 0] == pytest.approx(still.centers[0, foot_r, 0])


@pytest.mark.parametrize("heading", [0.0, 0.7, math.pi / 2, -2.5])
def test_heading_turns_and_feet_xy_moves_the_whole_body(heading: float) -> None:
    base = pose()
    moved = pose(xy=(3.0, -2.0), heading=heading)
    c, s = math.cos(heading), math.sin(heading)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    expected = base.centers[0] @ rot.T + [3.0, -2.0, 0.0]
    np.testing.assert_allclose(moved.centers[0], expected, atol=1e-12)
    np.testing.assert_allclose(moved.radii, base.radii)


def test_many_bodies_at_once_equal_one_at_a_time() -> None:
    rng = np.random.default_rng(4)
    shape = BodyShape.sample(rng, 6)
    xy, heading, phase = rng.uniform(-5, 5, (6, 2)), rng.uniform(-3, 3, 6), rng.uniform(0, 6, 6)
    speed, posture = rng.uniform(0, 1.8, 6), np.array([0, 1, 2, 0, 2, 1])
    together = pose_bodies(shape, xy, heading, phase, speed, posture)
    for i in range(6):
        one = slice(i, i + 1)
        alone = pose_bodies(shape[one], xy[one], heading[one], phase[one], speed[one], posture[one])
        np.testing.assert_allclose(together.centers[i], alone.centers[0], atol=1e-12)
        np.testing.assert_allclose(together.axes[i], alone.axes[0], atol=1e-12)


def test_axes_are_orthonormal_rotations() -> None:
    prims = pose(n=2, phase=1.0, speed=1.5, posture=Posture.WALKING)
    gram = np.einsum("npki,npkj->npij", prims.axes, prims.axes)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-12)


@pytest.mark.parametrize("k", [56, 200, 256, 400])
def test_surface_samples_lie_on_their_ellipsoid_with_outward_normals(k: int) -> None:
    prims = pose(n=3, phase=2.0, speed=1.2, posture=Posture.WALKING)
    s = prims.surface_samples(k)
    assert s.points.shape == (3, k, 3) and s.normals.shape == (3, k, 3) and s.part.shape == (k,)
    assert set(s.part.tolist()) == set(range(len(PART_NAMES)))  # every part gets points
    c, ax, r = prims.centers[:, s.part], prims.axes[:, s.part], prims.radii[:, s.part]
    local = np.einsum("nkji,nkj->nki", ax, s.points - c) / r
    np.testing.assert_allclose(np.linalg.norm(local, axis=-1), 1.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=-1), 1.0, atol=1e-12)
    assert np.all((s.normals * (s.points - c)).sum(-1) > 0)


def test_surface_samples_are_deterministic_and_spread_by_area() -> None:
    prims = pose()
    a, b = prims.surface_samples(256), prims.surface_samples(256)
    np.testing.assert_array_equal(a.points, b.points)
    counts = np.bincount(a.part, minlength=len(PART_NAMES))
    assert counts[PART_INDEX["torso"]] > counts[PART_INDEX["head"]] > counts[PART_INDEX["foot_left"]]


def test_contains_finds_points_inside_the_body() -> None:
    prims = pose(xy=(1.0, 1.0))
    inside = prims.contains(np.array([[1.0, 1.0, 1.2], [1.0, 1.0, 1.6], [2.0, 1.0, 1.2], [1.0, 1.0, 1.9]]))
    assert inside[:, 0].tolist() == [True, True, False, False]


def test_lower_parts_are_shins_and_feet() -> None:
    assert sorted(PART_NAMES[i] for i in LOWER_PARTS) == ["foot_left", "foot_right", "shin_left", "shin_right"]


def test_sampled_shapes_are_adult_sized() -> None:
    shape = BodyShape.sample(np.random.default_rng(0), 2000)
    assert shape.height.min() >= 1.5 and shape.height.max() <= 1.95
    assert 1.68 < shape.height.mean() < 1.76
    assert np.all((shape.shoulder_width > 0.3) & (shape.shoulder_width < 0.6))


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: pose().surface_samples(20), "points_per_body"),
        (lambda: BodyShape(np.ones(2), np.ones(3), np.ones(2)), "shoulder_width"),
    ],
)
def test_bad_arguments_are_refused(build, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build()
