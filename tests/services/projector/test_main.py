from __future__ import annotations

import numpy as np
import pytest

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


def box_around(camera, feet_xy: tuple[float, float], height: float = 1.7, radius: float = 0.3) -> tuple[float, ...]:
    x, y = feet_xy
    corners = np.array([[x + dx, y + dy, z] for dx in (-radius, radius) for dy in (-radius, radius) for z in (0.0, height)])
    uv = camera.project(corners)
    return (*uv.min(axis=0), *uv.max(axis=0))


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
