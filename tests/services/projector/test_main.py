from __future__ import annotations

import numpy as np
import pytest

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
