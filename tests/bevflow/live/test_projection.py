from __future__ import annotations

import numpy as np
import pytest

from bevflow.cylinder import fit_cylinders
from bevflow.detections import Boxes
from bevflow.fusion import position_covariance
from bevflow.live.projection import CameraProjection, fit_reach_m
from bevflow.site import parse_site
from tests.services.projector.test_main import SITE, box_around


@pytest.mark.parametrize(
    ("height", "radius", "reach"),
    [(4.0, None, None), (1.7, 10.0, None), (2.4, 10.0, None), (4.0, 3.0, 6.5), (5.5, 8.5, 8.5 * 5.5 / 3.5 + 0.5)],
)
def test_fit_reach_is_where_a_kept_persons_box_can_land(height, radius, reach) -> None:
    assert fit_reach_m(height, radius) == (None if reach is None else pytest.approx(reach))


@pytest.mark.parametrize(
    ("camera", "radius", "feet", "kept"),
    [
        ("a", None, [(1.0, 0.5), (4.5, 0.0)], [(1.0, 0.5), (4.5, 0.0)]),
        ("a", 3.0, [(1.0, 0.5), (4.5, 0.0)], [(1.0, 0.5)]),  # past 3 m plus the 0.5 m margin
        ("b", 3.0, [(4.0, -1.5), (9.0, 0.0)], [(4.0, -1.5)]),
    ],
)
def test_cylinders_of_one_camera_within_its_reporting_radius(camera, radius, feet, kept) -> None:
    text = SITE if radius is None else SITE.replace("[1024, 1024]", "[1024, 1024], monitored_radius_m: 3.0")
    site = parse_site(text)
    boxes = Boxes(xyxy=np.array([box_around(site.camera(camera), f) for f in feet]))
    cylinders = CameraProjection(site).project(camera, boxes)
    index = site.camera_index(camera)
    assert cylinders.camera.tolist() == [index] * len(kept)
    np.testing.assert_allclose(cylinders.xy, kept, atol=0.15)
    cameras = [site.camera(c) for c in site.camera_ids]
    np.testing.assert_array_equal(cylinders.covariance, position_covariance(cylinders, cameras))


def test_the_projection_is_the_cylinder_fit_where_nothing_is_cut() -> None:
    site = parse_site(SITE)
    boxes = Boxes(xyxy=np.array([box_around(site.camera("a"), f) for f in ((1.0, 0.5), (-2.0, 1.0))]))
    expected = fit_cylinders(site.camera("a"), boxes, camera_index=0)
    np.testing.assert_array_equal(CameraProjection(site).project("a", boxes).xy, expected.xy)


def test_a_camera_the_site_lacks_is_an_error_naming_its_cameras() -> None:
    with pytest.raises(ValueError, match="no camera 'zz'; its cameras are a, b"):
        CameraProjection(parse_site(SITE)).project("zz", Boxes.empty())


SIDE_SITE = """
site: corridor
cameras:
  - {id: s, model: pinhole, image_size: [1920, 1080], intrinsics: {fx: 1700, fy: 1700, cx: 960, cy: 540},
     pose: {position: [0, 0, 2.5], pitch_deg: 70}}
"""


def test_a_side_camera_measures_each_persons_head_height() -> None:
    site = parse_site(SIDE_SITE)
    camera = site.camera("s")
    heights = (1.60, 1.85)
    boxes = Boxes(xyxy=np.array([box_around(camera, (0.4 * k, 5.0), h) for k, h in enumerate(heights)]))
    cylinders = CameraProjection(site).project("s", boxes)
    np.testing.assert_allclose(cylinders.stature, heights, atol=0.08)
