"""A site file to calibrate, and the pose its first camera really has: the file says it hangs at
(5, 4, 4) looking straight down; in truth it is a little off and turned. Floor points seen through
the true pose are what an installer would click."""

from __future__ import annotations

import numpy as np

from bevflow.camera import Camera, rotation_from_ypr
from bevflow.site import Site, parse_site

SITE_YAML = """\
# the hall by the gate; calibrated on site
site: calib-hall
cameras:
  - id: gate   # over the main door
    image_size: [800, 800]
    intrinsics: {fx: 250, fy: 250, cx: 400, cy: 400}
    pose: {position: [5, 4, 4]}   # measured with a tape, to be calibrated
    monitored_radius_m: 5
  - id: shop
    image_size: [800, 800]
    intrinsics: {fx: 250, fy: 250, cx: 400, cy: 400}
    pose: {position: [12, 4, 4]}
zones:
  - {id: entrance, polygon: [[3, 2], [7, 2], [7, 6], [3, 6]], capacity: 10}
floor: [0, 0, 16, 8]
"""

TRUE_POSITION = np.array([5.25, 3.85, 4.05])
TRUE_YPR = (8.0, 1.0, 0.0)
FLOOR_POINTS = [(3.0, 2.0), (7.0, 2.0), (7.0, 6.0), (3.0, 6.0), (5.0, 1.5), (5.0, 6.5), (2.5, 4.0), (7.5, 4.0)]


def site() -> Site:
    return parse_site(SITE_YAML)


def true_camera() -> Camera:
    """The first camera with its true pose."""
    R = rotation_from_ypr(*TRUE_YPR)
    return site().camera("gate").with_pose(R, -R @ TRUE_POSITION)


def true_pixels(points: list[tuple[float, float]] = FLOOR_POINTS) -> np.ndarray:
    world = np.array([(x, y, 0.0) for x, y in points])
    return true_camera().project(world)
