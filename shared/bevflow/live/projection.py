"""One camera's person boxes to world cylinders, as the live projector does it.

``CameraProjection(site).project(camera_id, boxes)`` is the projector service's work without
the bus, so a replay of recorded boxes (``bevflow.evaluation.replay``) scores exactly what runs
live. Per camera it keeps the paper's cylinder-fit lookup table (``bevflow.cylinder``), fitted
only as far out as a reported person's box can land (``fit_reach_m``); it drops the cylinders
beyond the camera's reporting radius (its monitored radius plus a margin, where its feet
estimates are still good enough to fuse); and it gives each cylinder the covariance of its feet
position (``bevflow.fusion.position_covariance``) and the person's head height as the box
measures it (``bevflow.stature``), which need the camera and the box and so are computed here
rather than in the tracker, which fuses every camera in one thread.
"""

from __future__ import annotations

from bevflow.cylinder import CylinderGrid, ProjectionMethod, fit_cylinders
from bevflow.detections import Boxes, Cylinders
from bevflow.fusion import with_position_covariance
from bevflow.site import Site
from bevflow.stature import with_stature

# Each camera's lookup table fills in wherever its boxes' anchors land, 24 kB per m² of floor,
# and keeps what it filled. With the fit's default reach of 100 m a table could grow to 930 MB;
# fitting only where a person could still be kept (``fit_reach_m``) bounds it by that reach:
# 22 MB for a 5.5 m camera reporting to 8.5 m.
TALLEST_M = 2.0


def fit_reach_m(camera_height_m: float, reporting_radius_m: float | None) -> float | None:
    """How far from the camera a box's anchor can land on the floor for a person within the
    reporting radius (None: anywhere). A box cut down to the head has its anchor where the ray
    past the head meets the floor, ``height / (height - TALLEST_M)`` times farther out than the
    person; a camera not well above people's heads (a side view) gets no limit."""
    if reporting_radius_m is None or camera_height_m < TALLEST_M + 0.5:
        return None
    return reporting_radius_m * camera_height_m / (camera_height_m - TALLEST_M) + 0.5


class CameraProjection:
    """Every camera of ``site``: boxes in, that camera's cylinders out (``camera`` set to its
    index in the site, as fusion takes them). ``method`` is a ``bevflow.cylinder.METHODS`` name."""

    def __init__(self, site: Site, method: ProjectionMethod = "cylinder") -> None:
        self.site = site
        self.method = method
        self._cameras = [site.camera(c) for c in site.camera_ids]  # by index, as fusion takes them
        reach = [fit_reach_m(float(cam.center[2]), c.reporting_radius_m) for cam, c in zip(self._cameras, site.cameras, strict=True)]
        self._grids = [CylinderGrid() if r is None else CylinderGrid(max_range_m=r) for r in reach]

    def project(self, camera_id: str, boxes: Boxes) -> Cylinders:
        """The cylinders of ``camera_id``'s boxes within its reporting radius, with their feet
        covariance. ValueError naming the site's cameras for a camera it does not have."""
        index = self.site.camera_index(camera_id)
        camera = self._cameras[index]
        cylinders = fit_cylinders(camera, boxes, self.method, self._grids[index], camera_index=index)
        near = cylinders.near(camera.center, self.site.cameras[index].reporting_radius_m)
        cylinders = with_stature(camera, boxes[near], cylinders[near], self.method)
        return with_position_covariance(cylinders, self._cameras)
