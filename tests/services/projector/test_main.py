from __future__ import annotations

import numpy as np
import pytest

from bevflow.cylinder import box_anchor, fit_cylinders
from bevflow.fusion import position_covariance
from bevflow.schemas import Detections2D
from bevflow.site import parse_site

from bevflow_services.projector.main import Projector

SITE = """
site: hall
cameras:
  - {id: a, image_size: [1024, 1024], intrinsics: {fx: 300, fy: 300, cx: 511.5, cy: 511.5}, pose: {position: [0, 0, 4]}}
  - {id: b, image_size: [1024, 1024], intrinsics: {fx: 300, fy: 300, cx: 511.5, cy: 511.5}, pose: {position: [5, 0, 4]}}
"""


def box_of_part(camera, feet_xy: tuple[float, float], low: float, high: float, radius: float = 0.3) -> tuple[float, ...]:
    """The image box of a person's body from ``low`` to ``high`` metres above the floor."""
    x, y = feet_xy
    corners = np.array([[x + dx, y + dy, z] for dx in (-radius, radius) for dy in (-radius, radius) for z in (low, high)])
    uv = camera.project(corners)
    return (*uv.min(axis=0), *uv.max(axis=0))


def box_around(camera, feet_xy: tuple[float, float], height: float = 1.7) -> tuple[float, ...]:
    return box_of_part(camera, feet_xy, 0.0, height)


@pytest.mark.parametrize(("camera", "feet"), [("a", (1.0, 0.5)), ("b", (4.0, -1.5))])
def test_boxes_become_cylinders_at_the_feet(camera: str, feet: tuple[float, float]) -> None:
    site = parse_site(SITE)
    message = Detections2D(camera=camera, seq=7, capture_ns=123, boxes=[box_around(site.camera(camera), feet)])
    result = Projector(site).project(message)
    assert (result.camera, result.seq, result.capture_ns) == (camera, 7, 123)
    (cylinder,) = result.cylinders
    assert cylinder.xy == pytest.approx(feet, abs=0.1)


def test_unknown_camera_is_skipped_and_remembered() -> None:
    projector = Projector(parse_site(SITE))
    assert projector.project(Detections2D(camera="zz", seq=0, capture_ns=0, boxes=[(0, 0, 10, 10)])) is None
    assert projector.unknown_cameras == {"zz"}


def test_cylinders_carry_the_covariance_fusion_would_compute() -> None:
    site = parse_site(SITE)
    boxes = [box_around(site.camera("b"), feet) for feet in ((4.0, -1.5), (6.0, 1.0))]
    result = Projector(site).project(Detections2D(camera="b", seq=1, capture_ns=5, boxes=boxes))
    cylinders = result.to_cylinders(camera_index=1)
    cameras = [site.camera(c) for c in site.camera_ids]
    expected = position_covariance(cylinders, cameras)
    np.testing.assert_array_equal(cylinders.covariance, expected)
    assert (np.linalg.eigvalsh(expected) > 0).all()


@pytest.mark.parametrize(
    ("radius", "kept"),
    [
        (None, [(1.0, 0.5), (4.5, 0.0)]),
        (3.0, [(1.0, 0.5)]),  # 4.5 m out is past 3 m plus the 0.5 m edge margin
        (4.2, [(1.0, 0.5), (4.5, 0.0)]),  # within the margin: kept
    ],
)
def test_people_beyond_the_monitored_radius_are_left_to_other_cameras(radius, kept) -> None:
    text = SITE if radius is None else SITE.replace("pose: {position: [0, 0, 4]}}", f"pose: {{position: [0, 0, 4]}}, monitored_radius_m: {radius}}}")
    site = parse_site(text)
    boxes = [box_around(site.camera("a"), feet) for feet in ((1.0, 0.5), (4.5, 0.0))]
    result = Projector(site).project(Detections2D(camera="a", seq=1, capture_ns=5, boxes=boxes))
    assert [c.xy for c in result.cylinders] == [pytest.approx(f, abs=0.15) for f in kept]


@pytest.mark.parametrize("radius", [None, 2.0, 3.0])
def test_fitting_only_near_the_reporting_radius_keeps_exactly_what_a_full_fit_keeps(radius) -> None:
    # People all over the image, most far past the radius, a third of them seen only from the
    # shoulders up (their boxes' anchors land far out): the projector fits boxes only as far out as
    # a kept person's can land (so each camera's lookup table stays small), and still publishes
    # the same cylinders as fitting every box with the default reach and dropping the far ones.
    text = SITE if radius is None else SITE.replace("pose: {position: [0, 0, 4]}}", f"pose: {{position: [0, 0, 4]}}, monitored_radius_m: {radius}}}")
    site = parse_site(text)
    camera = site.camera("a")
    rng = np.random.default_rng(3)
    distance, angle, low = rng.uniform(0.0, 9.0, 90), rng.uniform(0, 2 * np.pi, 90), rng.choice([0.0, 0.0, 1.3], 90)
    edge = (radius or 3.0) + 0.1  # and four seen from the shoulders up just inside the reporting radius
    distance, angle, low = np.r_[distance, [edge] * 4], np.r_[angle, 0.0, 1.0, 2.0, 3.0], np.r_[low, [1.3] * 4]
    boxes = [box_of_part(camera, (d * np.cos(a), d * np.sin(a)), z, 1.7) for d, a, z in zip(distance, angle, low, strict=True)]
    message = Detections2D(camera="a", seq=1, capture_ns=5, boxes=boxes)
    full = fit_cylinders(camera, message.to_boxes(), camera_index=0)
    reporting = site.cameras[0].reporting_radius_m
    kept = full.near(camera.center, reporting) & np.isfinite(full.xy).all(axis=1)
    result = Projector(site).project(message)
    # The same to a micrometre: the two lookup tables tile the floor from different origins, and
    # OpenCV 5.1 projects a batch of points with rounding that depends on the batch (3e-8 m seen).
    assert [c.xy for c in result.cylinders] == [pytest.approx(tuple(xy), abs=1e-6) for xy in full.xy[kept]]
    if radius is not None:  # a kept person's anchor lay past the radius, and most people were dropped
        anchor = camera.pixels_to_plane(box_anchor(camera, message.to_boxes()), 0.0)[:, :2]
        assert (np.linalg.norm(anchor[kept], axis=1) > reporting).any()
        assert 0 < len(result.cylinders) < 50
