"""The cylinder fit against boxes made from known people: cuboids of the paper's model and
human-shaped silhouettes, through downward fisheyes at the paper's heights and a side-view pinhole."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from bevflow.camera import Camera, FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.cylinder import (
    METHODS,
    CylinderGrid,
    _RectTable,
    box_anchor,
    fit_cylinders,
    fit_cylinders_reference,
)
from bevflow.detections import Boxes

SQUARE = [(-1, -1), (1, -1), (1, 1), (-1, 1)]


# --- cameras and boxes, built here without the code under test ------------------------------------
def fisheye(height: float) -> FisheyeCamera:
    """A ceiling fisheye, slightly off the origin, turned and with a little lens distortion."""
    return FisheyeCamera.looking_down(
        position=(0.37, -0.21, height), image_size=(1024, 1024), fov_deg=185, yaw_deg=17.0,
        dist=(0.02, -0.005, 0.0, 0.0),
    )


def side_pinhole(pitch_deg: float = 70.0) -> PinholeCamera:
    """A WILDTRACK-like camera 2.5 m up, looking along +Y, ``90 - pitch`` degrees below level."""
    R = rotation_from_ypr(0.0, pitch_deg, 0.0)
    K = np.array([[1700.0, 0.0, 960.0], [0.0, 1700.0, 540.0], [0.0, 0.0, 1.0]])
    return PinholeCamera(K=K, dist=np.zeros(5), R=R, t=-R @ np.array([0.0, 0.0, 2.5]), image_size=(1920, 1080))


CAMERAS = {
    "fisheye 3.3 m": fisheye(3.3),
    "fisheye 5.5 m": fisheye(5.5),
    "fisheye 8.1 m": fisheye(8.1),
    "side pinhole": side_pinhole(),
}


def around(camera: Camera, radius: float, azimuth_deg: float) -> tuple[float, float]:
    """A floor point ``radius`` from the point below a fisheye, or ``radius`` ahead of the pinhole
    (and a little aside, within its view)."""
    if isinstance(camera, PinholeCamera):
        return (0.2 * radius * math.sin(math.radians(azimuth_deg)), radius)
    a = math.radians(azimuth_deg)
    return (camera.center[0] + radius * math.cos(a), camera.center[1] + radius * math.sin(a))


def clip_box(camera: Camera, uv: np.ndarray) -> list[float]:
    uv = uv[np.isfinite(uv).all(axis=1)]
    w, h = camera.image_size
    x0, y0 = uv.min(axis=0)
    x1, y1 = uv.max(axis=0)
    return [min(max(x0, 0), w - 1), min(max(y0, 0), h - 1), min(max(x1, 0), w - 1), min(max(y1, 0), h - 1)]


def cuboid_box(camera: Camera, x: float, y: float, height: float, radius: float) -> list[float]:
    """The paper's model: the bounding rectangle of the frustum's outer cuboid (upper radius 0.6 r)."""
    corners = [(x + sx * radius, y + sy * radius, 0.0) for sx, sy in SQUARE]
    corners += [(x + sx * 0.6 * radius, y + sy * 0.6 * radius, height) for sx, sy in SQUARE]
    return clip_box(camera, camera.project(np.array(corners)))


def _unit_person() -> np.ndarray:
    """Points on a standing person 1.75 m tall, feet centred on the origin: legs, torso, arms, head."""
    ring = np.linspace(0.0, 2.0 * np.pi, 20, endpoint=False)
    parts = [  # (centre x, half-width x, half-width y, z from, z to)
        (-0.1, 0.07, 0.07, 0.0, 0.85), (0.1, 0.07, 0.07, 0.0, 0.85),  # legs
        (0.0, 0.2, 0.12, 0.85, 1.45),  # torso
        (-0.25, 0.05, 0.05, 0.8, 1.42), (0.25, 0.05, 0.05, 0.8, 1.42),  # arms
    ]
    points = []
    for cx, ax, ay, z0, z1 in parts:
        t, z = np.meshgrid(ring, np.linspace(z0, z1, 6))
        points.append(np.stack([cx + ax * np.cos(t), ay * np.sin(t), z], axis=-1).reshape(-1, 3))
    t, elevation = np.meshgrid(ring, np.linspace(-np.pi / 2, np.pi / 2, 9))  # head: 0.1 m sphere
    head = [0.1 * np.cos(elevation) * np.cos(t), 0.1 * np.cos(elevation) * np.sin(t), 1.64 + 0.11 * np.sin(elevation)]
    points.append(np.stack(head, axis=-1).reshape(-1, 3))
    return np.concatenate(points)


UNIT_PERSON = _unit_person()


def person_points(height: float = 1.75, yaw_deg: float = 0.0) -> np.ndarray:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (UNIT_PERSON * np.array([1.0, 1.0, height / 1.75])) @ turn.T


def silhouette_box(camera: Camera, x: float, y: float, height: float = 1.75, yaw_deg: float = 0.0) -> list[float]:
    return clip_box(camera, camera.project(person_points(height, yaw_deg) + np.array([x, y, 0.0])))


def feet_error(fit, truth) -> np.ndarray:
    return np.linalg.norm(fit.xy - np.asarray(truth, dtype=float).reshape(-1, 2), axis=1)


# --- the grid ----------------------------------------------------------------------------------------
def test_default_grid_is_the_papers_sampling():
    grid = CylinderGrid()
    assert grid.diameters_m == pytest.approx((0.5, 0.65, 0.8, 0.95))
    assert grid.heights_m == pytest.approx((1.5, 1.7, 1.9))
    assert (2 * grid.half_cells + 1) ** 2 * len(grid.diameters_m) * len(grid.heights_m) == 1452
    assert (grid.top_ratio, grid.occlusion_ratio, grid.occluded_height_m) == (0.6, 0.1, 1.7)


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"step_m": 0.0}, "step_m"),
        ({"diameters_m": ()}, "diameters_m"),
        ({"heights_m": (1.7, -1.0)}, "heights_m"),
        ({"top_ratio": 1.5}, "top_ratio"),
        ({"weight_power": 0.0}, "weight_power"),
        ({"top_k": -1}, "top_k"),
        ({"touch_fraction": -0.1}, "touch_fraction"),
    ],
)
def test_grid_rejects_bad_settings(settings, message):
    with pytest.raises(ValueError, match=message):
        CylinderGrid(**settings)


# --- the anchor ---------------------------------------------------------------------------------------
def test_anchor_of_box_straight_out_from_fisheye_centre_is_its_near_edge_midpoint():
    cam = FisheyeCamera.looking_down(position=(0.0, 0.0, 3.3), image_size=(1001, 1001))
    # nadir at (500, 500); a box to the right of it, symmetric about the row y = 500
    assert box_anchor(cam, Boxes(xyxy=[[600.0, 480.0, 700.0, 520.0]]))[0] == pytest.approx([600.0, 500.0])


def test_anchor_of_diagonal_box_is_its_near_corner():
    cam = FisheyeCamera.looking_down(position=(0.0, 0.0, 3.3), image_size=(1001, 1001))
    assert box_anchor(cam, Boxes(xyxy=[[600.0, 600.0, 660.0, 660.0]]))[0] == pytest.approx([600.0, 600.0])


def test_anchor_is_the_nadir_when_the_box_contains_it():
    cam = FisheyeCamera.looking_down(position=(0.0, 0.0, 3.3), image_size=(1001, 1001))
    assert box_anchor(cam, Boxes(xyxy=[[480.0, 470.0, 540.0, 530.0]]))[0] == pytest.approx([500.0, 500.0])


def test_anchor_of_side_view_box_is_on_its_bottom_edge_toward_the_vanishing_point():
    cam = side_pinhole(70.0)
    nx, ny = cam.nadir_pixel()  # far below the image
    box = [1500.0, 300.0, 1600.0, 600.0]  # well right of the image centre column
    anchor = box_anchor(cam, Boxes(xyxy=[box]))[0]
    # the line from the centre (1550, 450) to the vanishing point crosses y = 600 here
    assert anchor == pytest.approx([1550.0 + (nx - 1550.0) * 150.0 / (ny - 450.0), 600.0])
    assert abs(anchor[0] - 1550.0) < 20.0  # near the bottom centre, not at the corner x = 1500


def test_anchor_of_level_camera_box_is_its_bottom_centre():
    level = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # optical axis +Y, image down = −Z
    base, t = side_pinhole(), -level @ np.array([0.0, 0.0, 2.5])
    cam = PinholeCamera(K=base.K, dist=base.dist, R=level, t=t, image_size=base.image_size)
    assert box_anchor(cam, Boxes(xyxy=[[1500.0, 300.0, 1600.0, 600.0]]))[0] == pytest.approx([1550.0, 600.0], abs=0.05)


def test_anchor_without_a_nadir_pixel_follows_the_image_of_down():
    # A level fisheye whose lens ends 74° off axis cannot see straight down; on its central column
    # the image of a vertical is vertical, so the feet end of a box there is its bottom centre.
    level = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    K = np.array([[300.0, 0.0, 500.0], [0.0, 300.0, 500.0], [0.0, 0.0, 1.0]])
    t = -level @ np.array([0.0, 0.0, 2.0])
    cam = FisheyeCamera(K=K, dist=np.array([-0.2, 0.0, 0.0, 0.0]), R=level, t=t, image_size=(1000, 1000))
    assert not np.isfinite(cam.nadir_pixel()).all()
    assert box_anchor(cam, Boxes(xyxy=[[470.0, 400.0, 530.0, 620.0]]))[0] == pytest.approx([500.0, 620.0])


# --- accuracy ----------------------------------------------------------------------------------------
LATTICE_RADII = {
    "fisheye 3.3 m": (0.0, 1.0, 2.0, 3.2),
    "fisheye 5.5 m": (0.0, 1.0, 2.5, 4.0, 7.0),
    "fisheye 8.1 m": (0.0, 1.0, 2.5, 4.0, 7.0),
    "side pinhole": (4.0, 7.0, 12.0, 18.0),
}
# Diameters up to 0.65 m: the anchor sits on the near corner of the cuboid's footprint, and for
# wider cylinders the true centre can lie beyond the paper's ±0.5 m window.
LATTICE_PEOPLE = [  # (camera, radius m, azimuth deg, diameter, height)
    (name, radius, 70.0 * i, diameter, height)
    for name, radii in LATTICE_RADII.items()
    for i, radius in enumerate(radii)
    for diameter, height in ((0.5, 1.7), (0.5, 1.5), (0.65, 1.9))
]


@pytest.mark.parametrize("name, radius, azimuth, diameter, height", LATTICE_PEOPLE)
def test_best_candidate_recovers_a_model_person_on_the_lattice_exactly(name, radius, azimuth, diameter, height):
    cam = CAMERAS[name]
    x, y = (round(v * 10) / 10 for v in around(cam, radius, azimuth))  # on the 0.1 m lattice
    fit = fit_cylinders(cam, Boxes(xyxy=[cuboid_box(cam, x, y, height, diameter / 2)]), grid=CylinderGrid(top_k=1))
    assert feet_error(fit, (x, y))[0] < 1e-6
    assert fit.score[0] == pytest.approx(1.0, abs=1e-5)
    assert not fit.occluded[0]
    if radius > 0.5:  # straight below a camera only the outline of the widest part shows
        assert (fit.height[0], fit.radius[0]) == pytest.approx((height, diameter / 2))


MODEL_TOLERANCE = {  # (mean, worst) feet error in metres
    "fisheye 3.3 m": (0.13, 0.25),
    "fisheye 5.5 m": (0.09, 0.17),
    "fisheye 8.1 m": (0.07, 0.12),
    "side pinhole": (0.32, 0.36),
}


@pytest.mark.parametrize("name", CAMERAS)
def test_model_people_off_the_lattice_are_placed_within_tolerance(name):
    cam = CAMERAS[name]
    radii = (5.0, 8.0, 12.0, 16.0) if name == "side pinhole" else (0.3, 1.2, 2.1, 3.0)
    truth = np.array([around(cam, r, a) for r in radii for a in (10.0, 100.0, 200.0)]) + 0.037
    boxes = Boxes(xyxy=[cuboid_box(cam, x, y, 1.62, 0.29) for x, y in truth])
    error = feet_error(fit_cylinders(cam, boxes), truth)
    mean_tol, worst_tol = MODEL_TOLERANCE[name]
    assert error.mean() < mean_tol
    assert error.max() < worst_tol


SILHOUETTE_RADII = {
    "fisheye 3.3 m": (0.0, 0.8, 1.6, 2.4, 3.2),
    "fisheye 5.5 m": (0.0, 1.5, 3.0, 5.0, 7.0),
    "fisheye 8.1 m": (0.0, 2.0, 4.0, 7.0, 9.5),
    "side pinhole": (4.0, 7.0, 10.0, 14.0, 18.0),
}


@functools.cache
def silhouette_people(name: str) -> tuple[np.ndarray, Boxes]:
    cam = CAMERAS[name]
    truth, boxes = [], []
    for i, radius in enumerate(SILHOUETTE_RADII[name]):
        for j, azimuth in enumerate((0.0, 40.0, 75.0, 160.0, 290.0)):
            x, y = around(cam, radius, azimuth)
            height, yaw = 1.6 + 0.05 * ((i + j) % 5), 37.0 * (i + 2 * j)
            truth.append((x, y))
            boxes.append(silhouette_box(cam, x, y, height, yaw))
    return np.array(truth), Boxes(xyxy=boxes)


SILHOUETTE_TOLERANCE = {  # (mean, worst) feet error in metres
    "fisheye 3.3 m": (0.08, 0.26),
    "fisheye 5.5 m": (0.08, 0.26),
    "fisheye 8.1 m": (0.08, 0.26),
    "side pinhole": (0.10, 0.20),
}


@pytest.mark.parametrize("name", CAMERAS)
def test_human_silhouettes_are_placed_within_tolerance(name):
    truth, boxes = silhouette_people(name)
    error = feet_error(fit_cylinders(CAMERAS[name], boxes), truth)
    mean_tol, worst_tol = SILHOUETTE_TOLERANCE[name]
    assert error.mean() < mean_tol
    assert error.max() < worst_tol


@pytest.mark.parametrize("name", CAMERAS)
def test_cylinder_beats_both_baselines_on_silhouettes(name):
    truth, boxes = silhouette_people(name)
    errors = {method: feet_error(fit_cylinders(CAMERAS[name], boxes, method), truth).mean() for method in METHODS}
    assert errors["cylinder"] < errors["nearest-point"] < errors["bbox-center"]


@pytest.mark.parametrize("name", ["fisheye 3.3 m", "fisheye 5.5 m", "fisheye 8.1 m"])
def test_sharper_weights_beat_the_papers_plain_iou_mean_on_model_people(name):
    cam = CAMERAS[name]
    truth = np.array([around(cam, r, a) for r in (1.0, 2.0, 3.0) for a in (20.0, 140.0)])
    boxes = Boxes(xyxy=[cuboid_box(cam, x, y, 1.7, 0.3) for x, y in truth])
    paper = feet_error(fit_cylinders(cam, boxes, grid=CylinderGrid(weight_power=1.0)), truth).mean()
    default = feet_error(fit_cylinders(cam, boxes), truth).mean()
    assert default < 0.7 * paper


# --- baselines ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["fisheye 3.3 m", "fisheye 5.5 m", "fisheye 8.1 m"])
def test_bbox_centre_is_biased_outward_and_nearest_point_inward_on_a_fisheye(name):
    cam = CAMERAS[name]
    truth, boxes = silhouette_people(name)
    distance = np.linalg.norm(truth - cam.center[:2], axis=1)
    away = distance > 1.0
    centre = np.linalg.norm(fit_cylinders(cam, boxes, "bbox-center").xy - cam.center[:2], axis=1)
    nearest = np.linalg.norm(fit_cylinders(cam, boxes, "nearest-point").xy - cam.center[:2], axis=1)
    assert np.all(centre[away] > distance[away] + 0.2)
    assert np.all(nearest[away] < distance[away])


def test_baselines_are_plain_floor_projections():
    cam = CAMERAS["fisheye 5.5 m"]
    _, boxes = silhouette_people("fisheye 5.5 m")
    np.testing.assert_allclose(fit_cylinders(cam, boxes, "bbox-center").xy, cam.pixels_to_plane(boxes.center)[:, :2])
    anchors = cam.pixels_to_plane(box_anchor(cam, boxes))[:, :2]
    np.testing.assert_allclose(fit_cylinders(cam, boxes, "nearest-point").xy, anchors)


# --- occlusion -----------------------------------------------------------------------------------------
def cut_near_side(camera: Camera, box: list[float], fraction: float) -> list[float]:
    """Hide the part of a box nearest the nadir, as a person or desk in front of the legs would."""
    x0, y0, x1, y1 = box
    nx, ny = camera.nadir_pixel()
    dx, dy = (x0 + x1) / 2 - nx, (y0 + y1) / 2 - ny
    if abs(dx) > abs(dy):
        return [x0 + fraction * (x1 - x0), y0, x1, y1] if dx > 0 else [x0, y0, x1 - fraction * (x1 - x0), y1]
    return [x0, y0 + fraction * (y1 - y0), x1, y1] if dy > 0 else [x0, y0, x1, y1 - fraction * (y1 - y0)]


@pytest.mark.parametrize("name", ["fisheye 3.3 m", "fisheye 5.5 m", "fisheye 8.1 m"])
@pytest.mark.parametrize("fraction", [0.4, 0.5])
def test_lower_body_occlusion_is_flagged_and_rebuilt_from_the_head(name, fraction):
    cam = CAMERAS[name]
    truth = np.array([around(cam, r, a) for r in (1.5, 2.5, 3.2) for a in (15.0, 130.0, 220.0)])
    boxes = Boxes(xyxy=[cut_near_side(cam, silhouette_box(cam, x, y, 1.72), fraction) for x, y in truth])
    fit = fit_cylinders(cam, boxes)
    unguarded = fit_cylinders(cam, boxes, grid=CylinderGrid(occlusion_ratio=1e9, touching_occlusion_ratio=1e9))
    assert fit.occluded.all()
    assert not unguarded.occluded.any()
    assert np.all(fit.height == 1.7)
    assert feet_error(fit, truth).max() < 0.2
    assert feet_error(fit, truth).mean() < 0.5 * feet_error(unguarded, truth).mean()


def test_side_view_keeps_a_weak_fit_rather_than_rebuild_from_a_shallow_head_ray():
    # From 2.5 m up, a head 10 m away is seen 0.8 m above head height: a 0.1 m height error would
    # move the rebuilt feet by 1.25 m, so the rebuild is refused; the fit is kept, marked weak.
    cam = CAMERAS["side pinhole"]
    truth = np.array([around(cam, r, a) for r in (6.0, 10.0, 14.0) for a in (0.0, 90.0, 270.0)])
    boxes = Boxes(xyxy=[cut_near_side(cam, silhouette_box(cam, x, y), 0.5) for x, y in truth])
    fit = fit_cylinders(cam, boxes)
    fires = fit_cylinders(cam, boxes, grid=CylinderGrid(max_head_slope=100.0, rebuild_occlusion_ratio=0.1)).occluded  # the test fires
    assert fires.any()
    assert not fit.occluded.any()
    untested = fit_cylinders(cam, boxes, grid=CylinderGrid(occlusion_ratio=math.inf, touching_occlusion_ratio=math.inf))
    np.testing.assert_allclose(fit.xy, untested.xy)
    np.testing.assert_array_equal(fit.score == 0.0, fires)  # weak exactly where the test fired
    assert (untested.score[fires] > 0.5).all()


def _occluded_pair(
    camera: Camera, near_xy: tuple[float, float], far_xy: tuple[float, float], kept: float
) -> list[list[float]]:
    """Boxes of a nearer person and of a farther one whose box keeps only its top ``kept`` part
    (its lower body hidden behind the nearer person), as a detector reports visible extents."""
    far = silhouette_box(camera, *far_xy)
    far[3] = far[1] + kept * (far[3] - far[1])
    return [silhouette_box(camera, *near_xy), far]


def test_side_view_box_whose_feet_end_meets_a_nearer_person_is_weak_even_when_slightly_cut():
    cam = CAMERAS["side pinhole"]
    near, cut = _occluded_pair(cam, (0.15, 6.0), (0.0, 7.5), kept=0.8)
    alone = fit_cylinders(cam, Boxes(xyxy=[cut]))
    # Alone, the paper's test does not fire, and the cut box is placed as a farther person.
    assert alone.score[0] > 0.5 and np.linalg.norm(alone.xy[0] - [0.0, 7.5]) > 1.0
    together = fit_cylinders(cam, Boxes(xyxy=[near, cut]))
    assert together.score[0] > 0.5 and together.score[1] == 0.0
    np.testing.assert_allclose(together.xy[1], alone.xy[0], atol=1e-6)  # weak, not moved
    # An uncut box behind someone, of a person of average height, is not weak: its fit does not
    # stick out (a short person's may; see the module docstring).
    whole = fit_cylinders(cam, Boxes(xyxy=[near, silhouette_box(cam, 0.0, 7.5)]))
    assert (whole.score > 0.5).all()


def test_the_second_cue_leaves_steep_views_to_the_papers_test():
    cam = CAMERAS["fisheye 3.3 m"]
    near_xy, far_xy = around(cam, 1.0, 30.0), around(cam, 1.7, 30.0)
    near = silhouette_box(cam, *near_xy)
    far = cut_near_side(cam, silhouette_box(cam, *far_xy), 0.4)
    alone = fit_cylinders(cam, Boxes(xyxy=[far]))
    together = fit_cylinders(cam, Boxes(xyxy=[near, far]))
    np.testing.assert_array_equal(together.xy[1], alone.xy[0])
    assert together.score[1] == alone.score[0] > 0.0


@pytest.mark.parametrize("kept, hidden_are_weak", [(0.5, True), (0.8, True), (1.0, False)])
def test_batched_fit_matches_the_reference_on_occluded_side_view_crowds(kept, hidden_are_weak):
    # Three lanes, each a nearer person and one behind them, cut to the top ``kept`` of their body.
    cam = CAMERAS["side pinhole"]
    boxes = []
    for lane, x in enumerate((-1.5, 0.0, 1.5)):
        boxes += _occluded_pair(cam, (x + 0.1 * lane, 5.0 + 2.0 * lane), (x, 6.3 + 2.0 * lane), kept)
    boxes = Boxes(xyxy=boxes)
    fast, slow = fit_cylinders(cam, boxes), fit_cylinders_reference(cam, boxes)
    assert (fast.score == 0.0).tolist() == [False, hidden_are_weak] * 3
    np.testing.assert_array_equal(fast.score == 0.0, slow.score == 0.0)
    assert np.nanmax(np.abs(fast.xy - slow.xy)) < 0.01
    np.testing.assert_allclose(fast.score, slow.score, atol=1e-4)


# --- the fast path against the oracle ------------------------------------------------------------------
GRIDS = [CylinderGrid(), CylinderGrid(weight_power=1.0), CylinderGrid(weight_power=2.5, top_k=40)]


@pytest.mark.parametrize("seed, name", list(enumerate(CAMERAS)))
@pytest.mark.parametrize("grid", GRIDS)
def test_batched_fit_matches_the_reference(seed, name, grid):
    cam = CAMERAS[name]
    rng = np.random.default_rng(seed)
    truth, boxes = silhouette_people(name)
    rows = boxes.xyxy[rng.choice(len(boxes), 5, replace=False)]
    cut = [cut_near_side(cam, list(b), 0.4) for b in rows[:2]]
    w, h = cam.image_size
    corner = rng.uniform([0, 0], [w * 0.8, h * 0.8], size=(2, 2))
    junk = np.concatenate([corner, corner + rng.uniform(20, 200, size=(2, 2))], axis=1)
    boxes = Boxes(xyxy=np.concatenate([rows, cut, junk]))
    fast, slow = fit_cylinders(cam, boxes, grid=grid), fit_cylinders_reference(cam, boxes, grid=grid)
    np.testing.assert_array_equal(np.isnan(fast.xy), np.isnan(slow.xy))
    assert np.nanmax(np.abs(fast.xy - slow.xy)) < 0.01
    np.testing.assert_allclose(fast.height, slow.height, atol=0.01)
    np.testing.assert_allclose(fast.radius, slow.radius, atol=0.01)
    np.testing.assert_allclose(fast.score, slow.score, atol=1e-4)
    np.testing.assert_array_equal(fast.occluded, slow.occluded)


# --- edges ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_no_boxes_give_no_cylinders(method):
    assert len(fit_cylinders(CAMERAS["fisheye 3.3 m"], Boxes.empty(), method)) == 0


def test_reference_on_no_boxes():
    assert len(fit_cylinders_reference(CAMERAS["fisheye 3.3 m"], Boxes.empty())) == 0


def test_unknown_method_is_rejected():
    with pytest.raises(ValueError, match="unknown projection method"):
        fit_cylinders(CAMERAS["fisheye 3.3 m"], Boxes.empty(), "centroid")  # type: ignore[arg-type]


@pytest.mark.parametrize("fit", [fit_cylinders, fit_cylinders_reference])
def test_unplaceable_rows_are_nan_and_do_not_disturb_the_others(fit):
    cam = side_pinhole(80.0)  # horizon at y = 240
    good = silhouette_box(cam, 0.5, 8.0)
    bad = [
        [np.nan, 10.0, 50.0, 60.0],  # corrupt
        [900.0, 10.0, 1000.0, 150.0],  # bottom above the horizon: never reaches the floor
        [700.0, 500.0, 700.0, 500.0],  # zero size: no candidate overlaps it
    ]
    alone = fit(cam, Boxes(xyxy=[good]))
    mixed = fit(cam, Boxes(xyxy=[bad[0], good, bad[1], bad[2]]))
    assert np.isnan(mixed.xy[[0, 2, 3]]).all()
    assert np.all(mixed.score[[0, 2, 3]] == 0.0)
    assert not mixed.occluded[[0, 2, 3]].any()
    np.testing.assert_allclose(mixed.xy[1], alone.xy[0])


def test_camera_index_is_recorded_and_equal_cameras_share_results():
    cam = CAMERAS["fisheye 5.5 m"]
    twin = FisheyeCamera(K=cam.K.copy(), dist=cam.dist.copy(), R=cam.R.copy(), t=cam.t.copy(), image_size=(1024, 1024))
    _, boxes = silhouette_people("fisheye 5.5 m")
    a, b = fit_cylinders(cam, boxes, camera_index=3), fit_cylinders(twin, boxes, camera_index=3)
    assert np.all(a.camera == 3)
    np.testing.assert_array_equal(a.xy, b.xy)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(
    "xyxy",
    [[[0, 0, 5, 5]], [[-50, -50, -10, -10]], [[0, 600, 3, 700]]],
    ids=["corner-outside-circle", "outside-image", "edge-sliver"],
)
def test_boxes_that_reach_no_floor_give_nan_rows_not_errors(method: str, xyxy: list) -> None:
    cam = FisheyeCamera.looking_down((0.0, 0.0, 5.5), (1280, 1280), fov_deg=185.0)
    fit = fit_cylinders(cam, Boxes(xyxy=np.array(xyxy, dtype=float)), method)
    assert len(fit) == 1 and np.isnan(fit.xy).all() and fit.score[0] == 0.0


@pytest.mark.parametrize("max_range_m", [2.0, 6.0])
def test_a_cameras_lookup_table_never_outgrows_its_reach(max_range_m: float) -> None:
    # Fill every tile of the reach in uneven batches: the table doubles as it fills, but never
    # past the whole reach.
    table = _RectTable(fisheye(3.3), CylinderGrid(max_range_m=max_range_m))
    side = table.slot_map.shape[0] * _RectTable.TILE
    cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2) + table.origin
    rng = np.random.default_rng(0)
    for part in np.array_split(rng.permutation(cells), 7):
        table.gather(part, half_cells=0)
        assert table.planes.shape[1] <= table.slot_map.size * _RectTable.TILE**2
    assert table.n_slots == table.slot_map.size
