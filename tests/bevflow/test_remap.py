"""Remap tables against frames rendered from a known floor texture."""

from __future__ import annotations

import doctest

import cv2
import numpy as np
import pytest

import bevflow.remap
from bevflow.camera import Camera, FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.remap import OUTSIDE, BevGrid, BevMosaic, atlas_layout, downward_view, rectify_maps, view_maps
from bevflow.site import parse_site

SQUARE_M = 1.0
DARK, LIGHT = 60, 190


def checker(xy: np.ndarray) -> np.ndarray:
    """The floor texture: 1 m squares, DARK where floor(x) + floor(y) is even."""
    parity = (np.floor(xy[:, 0] / SQUARE_M) + np.floor(xy[:, 1] / SQUARE_M)) % 2
    return np.where(parity == 0, DARK, LIGHT).astype(np.uint8)


def distance_to_checker_edge(xy: np.ndarray) -> np.ndarray:
    frac = np.mod(xy / SQUARE_M, 1.0)
    return SQUARE_M * np.minimum(frac, 1.0 - frac).min(axis=1)


def render_floor(cam: Camera, marker: int) -> np.ndarray:
    """A frame (h, w, 3) of the checkerboard floor Z = 0 seen by ``cam``: channel 0 the texture,
    channel 1 ``marker`` (to tell cameras apart after stitching), channel 2 255 where the floor is
    visible. Rendered by tracing every pixel's ray to the floor, independently of the tables."""
    w, h = cam.image_size
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    world = cam.pixels_to_plane(np.stack([uu.ravel(), vv.ravel()], axis=1), 0.0)
    seen = np.isfinite(world).all(axis=1)
    frame = np.zeros((h * w, 3), np.uint8)
    frame[seen, 0] = checker(world[seen, :2])
    frame[seen, 1] = marker
    frame[seen, 2] = 255
    return frame.reshape(h, w, 3)


def marker_of(k: int) -> int:
    return 20 + 50 * k


# A 12 × 8 m hall, four ceiling fisheyes at 3.3 m; every floor point is within 3.7 m of a camera.
HALL = (0.0, 0.0, 12.0, 8.0)
HALL_CAMERAS = [
    FisheyeCamera.looking_down((x, y, 3.3), (320, 320), fov_deg=180.0, yaw_deg=yaw)
    for (x, y), yaw in zip([(3, 2), (9, 2), (3, 6), (9, 6)], [0, 30, -90, 180], strict=True)
]
HALL_FRAMES = [render_floor(c, marker_of(k)) for k, c in enumerate(HALL_CAMERAS)]
HALL_MOSAIC = BevMosaic.build(HALL_CAMERAS, HALL, metres_per_pixel=0.04)


def _bev_world(mosaic: BevMosaic) -> np.ndarray:
    w, h = mosaic.size
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return mosaic.bev_pixels_to_world(np.stack([uu.ravel(), vv.ravel()], axis=1))


# --- the mosaic -----------------------------------------------------------------------------------
@pytest.mark.parametrize("fixed_point", [True, False])
def test_mosaic_reproduces_the_floor(fixed_point: bool) -> None:
    bev = HALL_MOSAIC.render(HALL_FRAMES, fixed_point=fixed_point).reshape(-1, 3)
    world = _bev_world(HALL_MOSAIC)
    assert (HALL_MOSAIC.camera_index >= 0).all(), "every hall pixel is seen by some camera"
    # Away from the squares' edges (a few camera pixels), sampling must give the texture exactly.
    clear = distance_to_checker_edge(world[:, :2]) > 0.2
    assert clear.mean() > 0.3
    np.testing.assert_array_equal(bev[clear, 0], checker(world[clear, :2]))
    assert (bev[:, 2] == 255).all()


def test_mosaic_reads_each_pixel_from_the_camera_it_names() -> None:
    bev = HALL_MOSAIC.render(HALL_FRAMES)
    expected = np.array([marker_of(k) for k in range(4)])[HALL_MOSAIC.camera_index]
    np.testing.assert_array_equal(bev[..., 1], expected)


@pytest.mark.parametrize(
    ("xy", "camera"),
    [
        pytest.param((3.0, 2.0), 0, id="under-0"),
        pytest.param((9.0, 2.0), 1, id="under-1"),
        pytest.param((3.0, 6.0), 2, id="under-2"),
        pytest.param((9.0, 6.0), 3, id="under-3"),
        pytest.param((5.9, 2.1), 0, id="nearer-0"),
        pytest.param((6.1, 2.1), 1, id="nearer-1"),
        pytest.param((8.0, 4.2), 3, id="nearer-3"),
        pytest.param((0.1, 7.9), 2, id="corner"),
    ],
)
def test_mosaic_picks_the_nearest_camera(xy: tuple[float, float], camera: int) -> None:
    u, v = np.rint(HALL_MOSAIC.world_to_bev_pixels(np.array([xy]))[0]).astype(int)
    assert HALL_MOSAIC.camera_index[v, u] == camera


# A narrow downward pinhole at the origin sees only ~1.1 m around it; a fisheye at x = 4 m sees far.
NARROW = PinholeCamera(
    K=[[100.0, 0, 49.5], [0, 100.0, 49.5], [0, 0, 1]],
    dist=[],
    R=rotation_from_ypr(0, 0, 0),
    t=[0.0, 0.0, 3.0],
    image_size=(100, 100),
)
WIDE = FisheyeCamera.looking_down((4.0, 0.0, 3.0), (256, 256), fov_deg=180.0)


@pytest.mark.parametrize(
    ("xy", "max_distance_m", "camera"),
    [
        pytest.param((0.5, 0.0), None, 0, id="nearest-sees-it"),
        pytest.param((1.8, 0.0), None, 1, id="nearest-cannot-see-it"),
        pytest.param((-3.0, 0.0), None, 1, id="far-but-only-one-sees-it"),
        pytest.param((-3.0, 0.0), [None, 5.0], -1, id="beyond-monitored-radius"),
        pytest.param((3.0, 0.0), 0.5, -1, id="beyond-common-radius"),
        pytest.param((3.8, 0.0), 0.5, 1, id="within-common-radius"),
    ],
)
def test_mosaic_only_uses_cameras_that_see_the_point(xy, max_distance_m, camera: int) -> None:
    mosaic = BevMosaic.build([NARROW, WIDE], (-4.0, -2.0, 6.0, 2.0), 0.05, max_distance_m=max_distance_m)
    u, v = np.rint(mosaic.world_to_bev_pixels(np.array([xy]))[0]).astype(int)
    assert mosaic.camera_index[v, u] == camera
    frames = [np.full((100, 100), 11, np.uint8), np.full((256, 256), 22, np.uint8)]
    assert mosaic.render(frames, border_value=7)[v, u] == {-1: 7, 0: 11, 1: 22}[camera]


def test_uncovered_pixels_get_the_border_value_in_every_channel() -> None:
    mosaic = BevMosaic.build([WIDE], (-4.0, -2.0, 6.0, 2.0), 0.05, max_distance_m=1.0)
    bev = mosaic.render([np.full((256, 256, 3), 100, np.uint8)], border_value=5)
    np.testing.assert_array_equal(bev[mosaic.camera_index < 0], 5)
    np.testing.assert_array_equal(bev[mosaic.camera_index == 0], 100)
    assert mosaic.map_x[mosaic.camera_index < 0].max() == OUTSIDE


def test_wrapped_atlas_renders_the_same_view() -> None:
    wrapped = BevMosaic.build(HALL_CAMERAS, HALL, metres_per_pixel=0.04, max_atlas_side=700)
    assert wrapped.atlas_size == (640, 640) and HALL_MOSAIC.atlas_size == (1280, 320)
    np.testing.assert_array_equal(wrapped.camera_index, HALL_MOSAIC.camera_index)
    np.testing.assert_array_equal(wrapped.render(HALL_FRAMES), HALL_MOSAIC.render(HALL_FRAMES))


def test_atlas_places_frames_at_their_offsets() -> None:
    mosaic = BevMosaic.build([NARROW, WIDE], (-4.0, -2.0, 6.0, 2.0), 0.05)
    frames = [np.full((100, 100), 1, np.uint8), np.full((256, 256), 2, np.uint8)]
    atlas = mosaic.atlas(frames)
    assert atlas.shape == (256, 356)
    assert (atlas[:100, :100] == 1).all() and (atlas[:, 100:] == 2).all() and (atlas[100:, :100] == 0).all()


@pytest.mark.parametrize(
    ("frames", "message"),
    [
        pytest.param([np.zeros((100, 100), np.uint8)], "expected 2 frames", id="too-few"),
        pytest.param(
            [np.zeros((100, 100), np.uint8), np.zeros((255, 256), np.uint8)],
            "frame 1: expected 256×256 uint8, got 255×256 uint8",
            id="wrong-size",
        ),
        pytest.param([np.zeros((100, 100), np.uint8), np.zeros((256, 256), np.float32)], "frame 1", id="wrong-dtype"),
        pytest.param(
            [np.zeros((100, 100, 3), np.uint8), np.zeros((256, 256), np.uint8)], "frame 1", id="wrong-channels"
        ),
    ],
)
def test_render_rejects_mismatched_frames(frames, message: str) -> None:
    mosaic = BevMosaic.build([NARROW, WIDE], (-4.0, -2.0, 6.0, 2.0), 0.05)
    with pytest.raises(ValueError, match=message):
        mosaic.render(frames)


def test_mosaic_from_site_uses_floor_and_monitored_radius() -> None:
    site = parse_site(
        """
floor: [0, 0, 10, 4]
cameras:
  - {id: a, image_size: [256, 256], intrinsics: {fx: 81.5, fy: 81.5, cx: 127.5, cy: 127.5}, pose: {position: [2, 2, 3]}, monitored_radius_m: 2.5}
  - {id: b, image_size: [256, 256], intrinsics: {fx: 81.5, fy: 81.5, cx: 127.5, cy: 127.5}, pose: {position: [8, 2, 3]}}
"""
    )
    mosaic = BevMosaic.from_site(site, metres_per_pixel=0.1)
    assert mosaic.size == (100, 40)
    world = _bev_world(mosaic)
    index = mosaic.camera_index.ravel()
    ground_a = np.hypot(world[:, 0] - 2, world[:, 1] - 2)
    assert (index[ground_a <= 2.4] == 0).all()
    # Beyond a's radius, b (no radius of its own) takes over even where a is nearer.
    assert (index[(ground_a > 2.6) & (world[:, 0] < 5)] == 1).all()


def test_mosaic_from_site_without_floor_needs_an_extent() -> None:
    site = parse_site(
        "cameras: [{id: a, image_size: [64, 64], intrinsics: {fx: 20, fy: 20, cx: 31.5, cy: 31.5}, pose: {position: [0, 0, 3]}}]"
    )
    with pytest.raises(ValueError, match="no 'floor' extent"):
        BevMosaic.from_site(site, 0.1)
    assert BevMosaic.from_site(site, 0.1, extent=(-1.0, -1.0, 1.0, 1.0)).size == (20, 20)


# --- the floor raster -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("extent", "mpp", "size", "world", "pixel"),
    [
        pytest.param((0, 0, 30, 20), 0.05, (600, 400), (0.025, 19.975), (0.0, 0.0), id="first-pixel-centre"),
        pytest.param((0, 0, 30, 20), 0.05, (600, 400), (29.975, 0.025), (599.0, 399.0), id="last-pixel-centre"),
        pytest.param((0, 0, 30, 20), 0.05, (600, 400), (0.0, 20.0), (-0.5, -0.5), id="top-left-corner"),
        pytest.param((-5, -2, 5, 2), 0.5, (20, 8), (0.0, 0.0), (9.5, 3.5), id="origin-in-the-middle"),
        pytest.param((0, 0, 1, 1), 0.3, (4, 4), (0.15, 0.85), (0.0, 0.0), id="extent-rounded-up"),
    ],
)
def test_grid_maps_world_and_pixels(extent, mpp: float, size, world, pixel) -> None:
    grid = BevGrid(extent, mpp)
    assert grid.size == size
    np.testing.assert_allclose(grid.world_to_pixels(np.array([world])), [pixel], atol=1e-9)
    np.testing.assert_allclose(grid.pixels_to_world(np.array([pixel]), z=1.5), [[*world, 1.5]], atol=1e-9)


def test_grid_round_trip_and_accepts_xyz() -> None:
    rng = np.random.default_rng(0)
    xyz = rng.uniform([0, 0, 0], [30, 20, 2], (100, 3))
    uv = HALL_MOSAIC.world_to_bev_pixels(xyz)
    np.testing.assert_allclose(HALL_MOSAIC.bev_pixels_to_world(uv)[:, :2], xyz[:, :2], atol=1e-9)
    assert HALL_MOSAIC.world_to_bev_pixels(np.zeros((0, 2))).shape == (0, 2)


@pytest.mark.parametrize(
    ("extent", "mpp", "message"),
    [
        ((0, 0, 10, 10), 0.0, "metres_per_pixel must be positive"),
        ((0, 0, 10, 10), -0.1, "metres_per_pixel must be positive"),
        ((10, 0, 0, 10), 0.1, "xmax > xmin"),
        ((0, 5, 10, 5), 0.1, "ymax > ymin"),
        ((0, 0, 400, 10), 0.01, "too large for cv2.remap"),
    ],
)
def test_grid_rejects_bad_extents(extent, mpp: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        BevGrid(extent, mpp)


@pytest.mark.parametrize(
    ("sizes", "max_side", "offsets", "atlas"),
    [
        pytest.param([(100, 50)], 1000, [(0, 0)], (100, 50), id="one"),
        pytest.param([(100, 50), (200, 80), (50, 10)], 1000, [(0, 0), (100, 0), (300, 0)], (350, 80), id="one-row"),
        pytest.param([(400, 50), (400, 80), (400, 10)], 1000, [(0, 0), (400, 0), (0, 80)], (800, 90), id="wraps"),
        pytest.param([(1000, 5), (1, 1)], 1000, [(0, 0), (0, 5)], (1000, 6), id="exactly-full"),
    ],
)
def test_atlas_layout(sizes, max_side: int, offsets, atlas) -> None:
    got_offsets, got_atlas = atlas_layout(sizes, max_side)
    np.testing.assert_array_equal(got_offsets, offsets)
    assert got_atlas == atlas


@pytest.mark.parametrize(
    ("sizes", "message"),
    [
        ([(1001, 5)], "camera 0: a 1001×5 px image is too large"),
        ([(600, 600), (600, 600)], "2 cameras do not fit one remap atlas"),
    ],
)
def test_atlas_layout_rejects_what_remap_cannot_take(sizes, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        atlas_layout(sizes, 1000)


def test_build_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="at least one camera"):
        BevMosaic.build([], HALL, 0.1)
    with pytest.raises(ValueError, match="max_distance_m has 1 values for 4 cameras"):
        BevMosaic.build(HALL_CAMERAS, HALL, 0.1, max_distance_m=[3.0])


# --- rectified views ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "cam",
    [
        pytest.param(
            FisheyeCamera.looking_down((0.5, -0.5, 3.0), (400, 400), fov_deg=185.0, yaw_deg=20.0), id="fisheye-down"
        ),
        pytest.param(
            FisheyeCamera(
                K=[[130.0, 0, 200.0], [0, 128.0, 198.0], [0, 0, 1]],
                dist=[0.02, -0.01, 0.002, 0.0],
                R=rotation_from_ypr(-40, 25, 5),
                t=-rotation_from_ypr(-40, 25, 5) @ [1.0, 1.0, 4.0],
                image_size=(400, 400),
            ),
            id="fisheye-tilted-distorted",
        ),
        pytest.param(
            PinholeCamera(
                K=[[300.0, 0, 199.5], [0, 300.0, 149.5], [0, 0, 1]],
                dist=[-0.1, 0.02, 0, 0, 0],
                R=rotation_from_ypr(10, 20, 0),
                t=-rotation_from_ypr(10, 20, 0) @ [0.0, 0.0, 3.0],
                image_size=(400, 300),
            ),
            id="pinhole-tilted",
        ),
    ],
)
def test_rectified_view_matches_a_straight_down_render(cam: Camera) -> None:
    out_size = (240, 200)
    virtual = downward_view(cam, out_size, fov_deg=100.0)
    map_x, map_y = rectify_maps(cam, out_size, fov_deg=100.0)
    assert map_x.shape == (200, 240) and map_x.dtype == np.float32 and map_y.dtype == np.float32
    rectified = cv2.remap(render_floor(cam, 1), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    direct = render_floor(virtual, 1)
    world = virtual.pixels_to_plane(
        np.stack(np.meshgrid(np.arange(240.0), np.arange(200.0)), axis=-1).reshape(-1, 2), 0.0
    )
    seen = (map_x.ravel() != OUTSIDE) & (rectified[..., 2].ravel() == 255)
    clear = seen & (distance_to_checker_edge(world[:, :2]) > 0.15)
    assert clear.mean() > 0.1  # thousands of pixels, whatever the camera
    np.testing.assert_array_equal(rectified[..., 0].ravel()[clear], direct[..., 0].ravel()[clear])


def test_rectified_view_looks_straight_down_from_the_camera() -> None:
    cam = FisheyeCamera.looking_down((1.0, 2.0, 4.0), (400, 400), fov_deg=185.0)
    tilted = cam.with_pose(rotation_from_ypr(70.0, 35.0, 0.0), -rotation_from_ypr(70.0, 35.0, 0.0) @ cam.center)
    map_x, map_y = rectify_maps(tilted, (101, 81), fov_deg=60.0)
    # The centre of the rectified view is the floor point straight below: the fisheye's nadir.
    np.testing.assert_allclose([map_x[40, 50], map_y[40, 50]], tilted.nadir_pixel(), atol=1e-3)
    virtual = downward_view(tilted, (101, 81), 60.0)
    np.testing.assert_allclose(virtual.center, tilted.center, atol=1e-12)
    np.testing.assert_allclose(virtual.R[2], [0, 0, -1], atol=1e-12)


@pytest.mark.parametrize(("yaw", "expected_yaw"), [(None, 70.0), (0.0, 0.0), (-30.0, -30.0)])
def test_rectified_view_follows_the_camera_heading_by_default(yaw, expected_yaw: float) -> None:
    cam = FisheyeCamera.looking_down((0.0, 0.0, 3.0), (200, 200), fov_deg=180.0, yaw_deg=70.0)
    virtual = downward_view(cam, (100, 100), 90.0, yaw_deg=yaw)
    np.testing.assert_allclose(virtual.R, rotation_from_ypr(expected_yaw, 0.0, 0.0), atol=1e-12)


def test_rectified_view_marks_what_the_camera_cannot_see() -> None:
    # A narrow pinhole rectified to a wide view: the outer ring reads from nowhere.
    map_x, map_y = rectify_maps(NARROW, (200, 200), fov_deg=120.0)
    assert map_x[0, 0] == OUTSIDE and map_y[0, 0] == OUTSIDE
    assert 0 <= map_x[100, 100] <= 99
    out = cv2.remap(
        np.full((100, 100), 50, np.uint8), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=3
    )
    assert out[0, 0] == 3 and out[100, 100] == 50


def test_view_maps_between_two_pinholes_at_one_centre_is_a_resize() -> None:
    # Same centre and orientation, half the focal length and size: a 2× downscale.
    big = PinholeCamera(
        K=[[200.0, 0, 99.5], [0, 200.0, 99.5], [0, 0, 1]], dist=[], R=np.eye(3), t=np.zeros(3), image_size=(200, 200)
    )
    small = big.scaled(0.5)
    map_x, map_y = view_maps(big, small)
    np.testing.assert_allclose(map_x[0, :3], [0.5, 2.5, 4.5], atol=1e-4)
    np.testing.assert_allclose(map_y[:3, 0], [0.5, 2.5, 4.5], atol=1e-4)


@pytest.mark.parametrize("fov", [0.0, 180.0, -10.0])
def test_downward_view_rejects_impossible_fov(fov: float) -> None:
    with pytest.raises(ValueError, match="0 < fov_deg < 180"):
        downward_view(WIDE, (10, 10), fov)


def test_docstring_examples() -> None:
    assert doctest.testmod(bevflow.remap).failed == 0
