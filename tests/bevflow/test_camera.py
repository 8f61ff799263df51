"""Camera models against OpenCV, round trips, unseen points, the nadir and the pose convention."""

from __future__ import annotations

import doctest
import math

import cv2
import numpy as np
import pytest

import bevflow.camera
from bevflow.camera import Camera, FisheyeCamera, PinholeCamera, make_camera, rotation_from_ypr


def _posed(cls: type[Camera], K, dist, position, ypr=(0.0, 0.0, 0.0), size=(1280, 960)) -> Camera:
    R = rotation_from_ypr(*ypr)
    return cls(
        K=np.asarray(K, dtype=np.float64),
        dist=np.asarray(dist, dtype=np.float64),
        R=R,
        t=-R @ np.asarray(position, dtype=np.float64),
        image_size=size,
    )


FISHEYES = {
    "equidistant-down": FisheyeCamera.looking_down((0.0, 0.0, 3.3), (1024, 1024), fov_deg=185.0),
    "distorted-yawed": _posed(
        FisheyeCamera,
        [[340.0, 0.0, 640.5], [0.0, 338.0, 478.0], [0, 0, 1]],
        [-0.02, 0.005, -0.001, 1e-4],
        (2.0, -1.0, 5.5),
        (30.0, 10.0, -5.0),
    ),
    "skewed-tilted": _posed(
        FisheyeCamera,
        [[420.0, 1.5, 630.0], [0.0, 425.0, 490.0], [0, 0, 1]],
        [0.1, -0.05, 0.01, -0.002],
        (-3.0, 4.0, 8.0),
        (-120.0, 45.0, 3.0),
    ),
}
PINHOLES = {
    "ideal": _posed(
        PinholeCamera, [[1000.0, 0.0, 640.0], [0.0, 1000.0, 480.0], [0, 0, 1]], [], (0.0, 0.0, 4.0), (0.0, 60.0, 0.0)
    ),
    "four-coef": _posed(
        PinholeCamera,
        [[900.0, 0.0, 650.0], [0.0, 905.0, 470.0], [0, 0, 1]],
        [-0.2, 0.05, 1e-3, -5e-4],
        (1.0, 2.0, 3.0),
        (45.0, 30.0, 0.0),
    ),
    "five-coef-skew": _posed(
        PinholeCamera,
        [[1100.0, 2.0, 630.0], [0.0, 1090.0, 500.0], [0, 0, 1]],
        [-0.3, 0.1, 1e-3, -2e-3, -0.02],
        (5.0, -2.0, 2.5),
        (-70.0, 65.0, 2.0),
    ),
    "rational": _posed(
        PinholeCamera,
        [[800.0, 0.0, 640.0], [0.0, 800.0, 480.0], [0, 0, 1]],
        [0.2, -0.1, 0.0, 0.0, 0.01, 0.3, -0.05, 0.01],
        (0.0, 0.0, 6.0),
        (10.0, 20.0, 0.0),
    ),
}
ALL_CAMERAS = {**FISHEYES, **PINHOLES}


def _points_in_view(cam: Camera, n: int, max_off_axis_deg: float, seed: int = 0) -> np.ndarray:
    """World points (n, 3) at 0.5–20 m from the camera, within a cone around its optical axis."""
    rng = np.random.default_rng(seed)
    theta = np.radians(max_off_axis_deg) * np.sqrt(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0.0, 2 * np.pi, n)
    dirs = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    xc = dirs * rng.uniform(0.5, 20.0, (n, 1))
    return (xc - cam.t) @ cam.R  # camera to world: R^T (xc - t)


def _floor_points_in_image(cam: Camera, z: float, n: int = 400, seed: int = 1) -> np.ndarray:
    """World points on the plane Z = z that land inside the camera's image."""
    rng = np.random.default_rng(seed)
    w, h = cam.image_size
    uv = rng.uniform([0.05 * w, 0.05 * h], [0.95 * w, 0.95 * h], (n * 4, 2))
    world = cam.pixels_to_plane(uv, z)
    world = world[np.isfinite(world).all(axis=1)]
    world = world[np.hypot(*(world[:, :2] - cam.center[:2]).T) < 30.0]
    assert len(world) >= n // 2, "test camera sees too little of the plane"
    return world[:n]


# --- agreement with OpenCV ------------------------------------------------------------------------
@pytest.mark.parametrize("name", FISHEYES)
def test_fisheye_projection_matches_opencv(name: str) -> None:
    cam = FISHEYES[name]
    world = _points_in_view(cam, 500, max_off_axis_deg=85.0)
    ours = cam.project(world)
    theirs, _ = cv2.fisheye.projectPoints(
        world.reshape(-1, 1, 3), cam.rvec, cam.t, cam.K, cam.dist, alpha=cam.K[0, 1] / cam.K[0, 0]
    )
    np.testing.assert_allclose(ours, theirs.reshape(-1, 2), rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", PINHOLES)
def test_pinhole_projection_matches_opencv(name: str) -> None:
    cam = PINHOLES[name]
    world = _points_in_view(cam, 500, max_off_axis_deg=40.0)
    ours = cam.project(world)
    theirs, _ = cv2.projectPoints(world, cam.rvec, cam.t, cam.K, cam.dist)
    np.testing.assert_allclose(ours, theirs.reshape(-1, 2), rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", [n for n, c in FISHEYES.items() if c.K[0, 1] == 0.0])
def test_fisheye_rays_match_opencv_undistort(name: str) -> None:
    # cv2.fisheye.undistortPoints ignores skew and gives x/z, so it only speaks for skew-free
    # cameras and rays in front of the lens.
    cam = FISHEYES[name]
    uv = cam.project(_points_in_view(cam, 300, max_off_axis_deg=80.0))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    theirs = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.dist, criteria=criteria).reshape(-1, 2)
    rays = cam.rays(uv)
    np.testing.assert_allclose(rays[:, :2] / rays[:, 2:], theirs, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("name", PINHOLES)
def test_pinhole_rays_match_opencv_undistort(name: str) -> None:
    cam = PINHOLES[name]
    uv = cam.project(_points_in_view(cam, 300, max_off_axis_deg=40.0))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    theirs = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.dist, criteria=criteria).reshape(-1, 2)
    rays = cam.rays(uv)
    np.testing.assert_allclose(rays[:, :2] / rays[:, 2:], theirs, rtol=1e-7, atol=1e-9)


# --- round trips ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALL_CAMERAS)
@pytest.mark.parametrize("z", [0.0, 1.7])
def test_pixel_to_plane_round_trip(name: str, z: float) -> None:
    cam = ALL_CAMERAS[name]
    world = _floor_points_in_image(cam, z)
    uv = cam.project(world)
    assert cam.in_image(uv).all()
    np.testing.assert_allclose(cam.pixels_to_plane(uv, z), world, rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", ALL_CAMERAS)
def test_rays_reproject_to_their_pixels(name: str) -> None:
    cam = ALL_CAMERAS[name]
    w, h = cam.image_size
    uu, vv = np.meshgrid(np.linspace(0, w - 1, 33), np.linspace(0, h - 1, 25))
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
    rays = cam.rays(uv)
    seen = np.isfinite(rays).all(axis=1)
    assert seen.mean() > 0.9
    np.testing.assert_allclose(cam.project_directions(rays[seen] * 7.0), uv[seen], rtol=0, atol=1e-6)
    # The world ray from the centre passes through the world point it came from.
    world = cam.center + 3.0 * cam.world_rays(uv[seen])
    np.testing.assert_allclose(cam.project(world), uv[seen], rtol=0, atol=1e-6)


def test_fisheye_beyond_90_degrees_round_trips() -> None:
    # A 190° lens sees a little above its own horizon; atan2 keeps those points projectable.
    cam = FisheyeCamera.looking_down((0.0, 0.0, 3.0), (1000, 1000), fov_deg=190.0)
    above = np.array([[10.0, 0.0, 3.5], [0.0, -10.0, 3.5], [-7.0, 7.0, 3.2]])
    uv = cam.project(above)
    assert cam.in_image(uv).all()
    rays = cam.world_rays(uv)
    assert (rays[:, 2] > 0).all()
    expected = (above - cam.center) / np.linalg.norm(above - cam.center, axis=1, keepdims=True)
    np.testing.assert_allclose(rays, expected, atol=1e-9)


def test_pixels_to_plane_takes_one_height_per_pixel() -> None:
    cam = FISHEYES["distorted-yawed"]
    world = np.array([[2.0, 0.0, 0.0], [3.0, -2.0, 1.0], [1.0, 1.0, 1.8]])
    np.testing.assert_allclose(cam.pixels_to_plane(cam.project(world), world[:, 2]), world, atol=1e-6)


# --- what a camera cannot see -------------------------------------------------------------------
FOLDING_FISHEYE = FisheyeCamera.looking_down((0.0, 0.0, 3.0), (1000, 1000), fov_deg=180.0, dist=(0.1, -0.3, 0.05, 0.0))
FOLDING_PINHOLE = _posed(
    PinholeCamera,
    [[1000.0, 0.0, 960.0], [0.0, 1000.0, 540.0], [0, 0, 1]],
    [-0.3, 0.0, 0.0, 0.0, 0.0],
    (0.0, 0.0, 5.0),
    size=(1920, 1080),
)


@pytest.mark.parametrize(
    ("cam", "camera_point"),
    [
        pytest.param(FISHEYES["equidistant-down"], [0.0, 0.0, 0.0], id="fisheye-at-centre"),
        pytest.param(FISHEYES["equidistant-down"], [0.0, 0.0, -2.0], id="fisheye-straight-behind"),
        # θd(θ) of this lens peaks at θ ≈ 59.8°; farther points would fold back into the image.
        pytest.param(FOLDING_FISHEYE, [math.tan(math.radians(70.0)), 0.0, 1.0], id="fisheye-past-fold"),
        pytest.param(PINHOLES["ideal"], [0.1, 0.2, -1.0], id="pinhole-behind"),
        pytest.param(PINHOLES["ideal"], [1.0, 0.0, 0.0], id="pinhole-sideways"),
        pytest.param(PINHOLES["ideal"], [0.0, 0.0, 0.0], id="pinhole-at-centre"),
        # k1 = −0.3 alone folds at r = 1/√0.9 ≈ 1.054.
        pytest.param(FOLDING_PINHOLE, [1.2, 0.0, 1.0], id="pinhole-past-fold"),
    ],
)
def test_unseen_points_project_to_nan(cam: Camera, camera_point: list[float]) -> None:
    xc = np.array([camera_point])
    assert np.isnan(cam.project_directions(xc)).all()
    assert np.isnan(cam.project((xc - cam.t) @ cam.R)).all()
    assert not cam.in_image(cam.project_directions(xc)).any()


@pytest.mark.parametrize(
    ("cam", "pixel"),
    [
        pytest.param(FOLDING_FISHEYE, [499.5 + 450.0, 499.5], id="fisheye-outside-reach"),
        pytest.param(FISHEYES["equidistant-down"], [511.5 + 1200.0, 511.5], id="fisheye-beyond-pi"),
        pytest.param(FOLDING_PINHOLE, [1900.0, 1070.0], id="pinhole-outside-reach"),
        pytest.param(FISHEYES["equidistant-down"], [np.nan, 3.0], id="nan-pixel"),
    ],
)
def test_unreachable_pixels_give_nan_rays(cam: Camera, pixel: list[float]) -> None:
    assert np.isnan(cam.rays(np.array([pixel]))).all()
    assert np.isnan(cam.pixels_to_plane(np.array([pixel]), 0.0)).all()


def test_folding_pinhole_keeps_points_just_inside_its_limit() -> None:
    # The limit from the polynomial is where the radial slope turns to zero.
    assert FOLDING_PINHOLE.max_radius == pytest.approx(1 / math.sqrt(0.9))
    k1, k2, k3, _ = FOLDING_FISHEYE.dist
    t = FOLDING_FISHEYE.max_theta**2
    assert 1 + 3 * k1 * t + 5 * k2 * t**2 + 7 * k3 * t**3 == pytest.approx(0.0, abs=1e-9)
    inside = np.array([[0.99 * FOLDING_PINHOLE.max_radius, 0.0, 1.0]])
    assert np.isfinite(FOLDING_PINHOLE.project_directions(inside)).all()


_F = FISHEYES["equidistant-down"].K[0, 0]


@pytest.mark.parametrize(
    ("pixel", "z"),
    [
        pytest.param([511.5, 511.5], 5.0, id="plane-above-a-downward-ray"),
        # 91.5° off the axis: the ray climbs and never meets the floor.
        pytest.param([511.5 + _F * math.radians(91.5), 511.5], 0.0, id="ray-above-horizon"),
    ],
)
def test_plane_out_of_reach_gives_nan(pixel: list[float], z: float) -> None:
    cam = FISHEYES["equidistant-down"]
    assert np.isfinite(cam.rays(np.array([pixel]))).all()
    assert np.isnan(cam.pixels_to_plane(np.array([pixel]), z)).all()


# --- nadir ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("yaw", [0.0, 37.0, -150.0])
@pytest.mark.parametrize("name", ["equidistant-down", "skewed-tilted"])
def test_nadir_of_downward_fisheye_is_principal_point(name: str, yaw: float) -> None:
    base = FISHEYES[name]
    R = rotation_from_ypr(yaw, 0.0, 0.0)
    cam = base.with_pose(R, -R @ np.array([1.0, 2.0, 4.0]))
    np.testing.assert_allclose(cam.nadir_pixel(), cam.K[:2, 2], atol=1e-9)


def test_nadir_of_tilted_fisheye_is_the_floor_point_below() -> None:
    cam = FISHEYES["distorted-yawed"]
    below = cam.center - np.array([0.0, 0.0, cam.center[2]])
    np.testing.assert_allclose(cam.nadir_pixel(), cam.project(below[None])[0], atol=1e-6)


@pytest.mark.parametrize("pitch", [60.0, 80.0, 90.0, 100.0])
@pytest.mark.parametrize("dist", [[], [-0.3, 0.0, 0.0, 0.0, 0.0], [-0.3, 0.1, 0.0, 0.0, 0.0]])
def test_nadir_of_side_view_pinhole_is_below_the_image(pitch: float, dist: list[float]) -> None:
    cam = _posed(
        PinholeCamera,
        [[1000.0, 0.0, 960.0], [0.0, 1000.0, 540.0], [0, 0, 1]],
        dist,
        (0.0, 0.0, 3.0),
        (25.0, pitch, 0.0),
        (1920, 1080),
    )
    u, v = cam.nadir_pixel()
    assert np.isfinite([u, v]).all()
    assert v > 1080 and abs(u - 960) < 1e-3 * v


# --- pose convention ------------------------------------------------------------------------------
def _axes_in_world(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image x, image y and optical axis as world directions."""
    return R[0], R[1], R[2]


@pytest.mark.parametrize(
    ("ypr", "image_x", "image_y", "optical_axis"),
    [
        pytest.param((0, 0, 0), (1, 0, 0), (0, -1, 0), (0, 0, -1), id="straight-down"),
        pytest.param((90, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, -1), id="yaw-turns-image-x-counterclockwise"),
        pytest.param(
            (30, 0, 0), (math.cos(math.pi / 6), 0.5, 0), (0.5, -math.cos(math.pi / 6), 0), (0, 0, -1), id="yaw-30"
        ),
        pytest.param(
            (0, 30, 0),
            (1, 0, 0),
            (0, -math.cos(math.pi / 6), -0.5),
            (0, 0.5, -math.cos(math.pi / 6)),
            id="pitch-tilts-toward-image-top",
        ),
        pytest.param((0, 90, 0), (1, 0, 0), (0, 0, -1), (0, 1, 0), id="pitch-90-is-upright-side-view"),
        pytest.param((90, 90, 0), (0, 1, 0), (0, 0, -1), (-1, 0, 0), id="yaw-then-pitch"),
        pytest.param((0, 0, 90), (0, -1, 0), (-1, 0, 0), (0, 0, -1), id="roll-about-optical-axis"),
    ],
)
def test_rotation_from_ypr_axes(ypr, image_x, image_y, optical_axis) -> None:
    x, y, z = _axes_in_world(rotation_from_ypr(*ypr))
    np.testing.assert_allclose(x, image_x, atol=1e-12)
    np.testing.assert_allclose(y, image_y, atol=1e-12)
    np.testing.assert_allclose(z, optical_axis, atol=1e-12)


def test_rotation_from_ypr_is_a_rotation() -> None:
    rng = np.random.default_rng(3)
    for yaw, pitch, roll in rng.uniform(-180, 180, (50, 3)):
        R = rotation_from_ypr(yaw, pitch, roll)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("yaw", "pitch", "floor_point"),
    [
        pytest.param(0.0, 45.0, (0.0, 5.0, 0.0), id="pitch-45-looks-at-+y"),
        pytest.param(90.0, 45.0, (-5.0, 0.0, 0.0), id="yawed-90-looks-at--x"),
        pytest.param(180.0, 30.0, (0.0, -5.0 * math.tan(math.radians(30)), 0.0), id="yawed-180"),
    ],
)
def test_tilted_camera_sees_expected_floor_point_at_image_centre(yaw: float, pitch: float, floor_point) -> None:
    R = rotation_from_ypr(yaw, pitch, 0.0)
    cam = FISHEYES["equidistant-down"].with_pose(R, -R @ np.array([0.0, 0.0, 5.0]))
    np.testing.assert_allclose(cam.project(np.array([floor_point]))[0], cam.K[:2, 2], atol=1e-9)


@pytest.mark.parametrize("yaw", [0.0, 60.0, -135.0])
def test_yaw_is_heading_of_image_right_edge(yaw: float) -> None:
    cam = FisheyeCamera.looking_down((1.0, 1.0, 4.0), (800, 800), fov_deg=180.0, yaw_deg=yaw)
    a = math.radians(yaw)
    u, v = cam.project(np.array([[1.0 + 2 * math.cos(a), 1.0 + 2 * math.sin(a), 0.0]]))[0]
    assert u > cam.K[0, 2] + 100 and v == pytest.approx(cam.K[1, 2], abs=1e-9)


# --- construction and helpers -------------------------------------------------------------------
def test_looking_down_fills_the_image_and_sits_at_its_position() -> None:
    cam = FisheyeCamera.looking_down((2.0, -3.0, 5.5), (1280, 960), fov_deg=180.0)
    np.testing.assert_allclose(cam.center, [2.0, -3.0, 5.5], atol=1e-12)
    # A ray 90° off axis meets the edge of the 960-px image circle.
    horizon = cam.project_directions(np.array([[1.0, 0.0, 0.0]]))[0]
    np.testing.assert_allclose(horizon, [639.5 + 480.0, 479.5], atol=1e-9)


def test_scaled_camera_matches_cv2_resize() -> None:
    cam = FISHEYES["distorted-yawed"]
    small = cam.scaled(0.5)
    assert small.image_size == (640, 480)
    w, h = cam.image_size
    # An image whose pixel values are their own column/row: after resizing, the value at a pixel is
    # where it came from in the original.
    cols = np.tile(np.arange(w, dtype=np.float32), (h, 1))
    rows = np.tile(np.arange(h, dtype=np.float32)[:, None], (1, w))
    resized = cv2.resize(np.dstack([cols, rows]), small.image_size, interpolation=cv2.INTER_LINEAR)
    world = _floor_points_in_image(cam, 0.0, n=50)
    uv_small = small.project(world)
    # Linear ramps interpolate exactly; read the resized image at the small camera's pixels.
    sampled = cv2.remap(
        resized, uv_small[:, 0].astype(np.float32)[None], uv_small[:, 1].astype(np.float32)[None], cv2.INTER_LINEAR
    )[0]
    np.testing.assert_allclose(sampled, cam.project(world), atol=0.05)


def test_with_pose_keeps_intrinsics_and_type() -> None:
    cam = PINHOLES["rational"]
    R = rotation_from_ypr(10.0, 20.0, 30.0)
    moved = cam.with_pose(R, np.array([0.1, 0.2, 0.3]))
    assert type(moved) is PinholeCamera and moved.image_size == cam.image_size
    np.testing.assert_array_equal(moved.K, cam.K)
    np.testing.assert_array_equal(moved.dist, cam.dist)
    np.testing.assert_allclose(moved.rvec, cv2.Rodrigues(R)[0].ravel(), atol=1e-12)


@pytest.mark.parametrize(
    ("kind", "dist", "expected"),
    [
        ("fisheye", [0, 0, 0, 0], FisheyeCamera),
        ("pinhole", [0, 0, 0, 0, 0], PinholeCamera),
        ("pinhole", [], PinholeCamera),
    ],
)
def test_make_camera_picks_the_model(kind, dist, expected) -> None:
    cam = make_camera(kind, np.eye(3), np.asarray(dist, dtype=float), np.eye(3), np.zeros(3), (10, 10))
    assert type(cam) is expected and cam.kind == kind


@pytest.mark.parametrize(
    ("cls", "dist", "message"),
    [
        (FisheyeCamera, [0.0] * 5, "4 coefficients"),
        (FisheyeCamera, [], "4 coefficients"),
        (PinholeCamera, [0.0] * 3, "0, 4, 5 or 8"),
        (PinholeCamera, [0.0] * 14, "0, 4, 5 or 8"),
    ],
)
def test_wrong_distortion_length_raises(cls, dist, message) -> None:
    with pytest.raises(ValueError, match=message):
        cls(K=np.eye(3), dist=np.asarray(dist), R=np.eye(3), t=np.zeros(3), image_size=(10, 10))


def test_camera_arrays_are_read_only() -> None:
    cam = FISHEYES["equidistant-down"]
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0


def test_docstring_examples() -> None:
    assert doctest.testmod(bevflow.camera).failed == 0


@pytest.mark.parametrize(
    ("ypr", "tilt"),
    [((0.0, 0.0, 0.0), 0.0), ((30.0, 63.0, 0.0), 63.0), ((200.0, 90.0, 10.0), 90.0), ((0.0, 120.0, 0.0), 120.0)],
    ids=["straight down", "a side camera", "level", "looking up"],
)
def test_tilt_is_the_optical_axis_angle_from_straight_down(ypr: tuple[float, float, float], tilt: float) -> None:
    R = rotation_from_ypr(*ypr)
    camera = PinholeCamera(K=np.eye(3), R=R, t=np.zeros(3), dist=np.zeros(5), image_size=(640, 480))
    assert camera.tilt_deg == pytest.approx(tilt) == bevflow.camera.tilt_deg(R)
