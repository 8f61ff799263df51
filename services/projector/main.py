"""Turn each camera's 2D person boxes into world cylinders with that camera's calibration.

    bevflow serve projector --site site.yaml

Subscribes to every camera's detections of the site and publishes one ``CameraCylinders`` per
detections message. The fit is the paper's 3D cylinder estimation (``bevflow.cylinder``); its
per-camera lookup tables are built on a camera's first message. Each cylinder carries the
covariance of its feet position (``bevflow.fusion.position_covariance``): it needs the camera,
which is at hand here, and computing it once per detection here spares the tracker, which fuses
every camera in one thread, from projecting every cylinder again. Messages from cameras the site
does not know are counted and skipped, never fatal. Under overload the oldest detections are
dropped (counted), so what is published stays current.
"""

from __future__ import annotations

import argparse
import logging

from bevflow.cylinder import METHODS, CylinderGrid, fit_cylinders
from bevflow.fusion import with_position_covariance
from bevflow.schemas import CameraCylinders, Detections2D
from bevflow.site import Site

from bevflow_services import bus
from bevflow_services.cli.serve import service_site, stop_on_signals

log = logging.getLogger(__name__)
SERVICE = "projector"
# Each camera's lookup table (``bevflow.cylinder``) fills in wherever its boxes' anchors land,
# 24 kB per m² of floor, and keeps what it filled. With the fit's default reach of 100 m a table
# could grow to 930 MB; fitting only where a person could still be kept (``fit_reach_m``) bounds
# it by that reach: 22 MB for a 5.5 m camera reporting to 8.5 m.
TALLEST_M = 2.0


def fit_reach_m(camera_height_m: float, reporting_radius_m: float | None) -> float | None:
    """How far from the camera a box's anchor can land on the floor for a person within the
    reporting radius (None: anywhere). A box cut down to the head has its anchor where the ray
    past the head meets the floor, ``height / (height - TALLEST_M)`` times farther out than the
    person; a camera not well above people's heads (a side view) gets no limit."""
    if reporting_radius_m is None or camera_height_m < TALLEST_M + 0.5:
        return None
    return reporting_radius_m * camera_height_m / (camera_height_m - TALLEST_M) + 0.5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("projector")
    group.add_argument("--method", choices=METHODS, default="cylinder",
                       help="how a box becomes a floor position (default: the paper's cylinder fit)")
    group.add_argument("--queue", type=int, default=64,
                       help="detections kept waiting before the oldest are dropped (default 64)")


class Projector:
    """The service's work, apart from the bus: one detections message in, cylinders out."""

    def __init__(self, site: Site, method: str = "cylinder") -> None:
        self.site = site
        self.method = method
        self.unknown_cameras: set[str] = set()
        self._cameras = [site.camera(c) for c in site.camera_ids]  # by index, as fusion takes them
        reach = [fit_reach_m(float(cam.center[2]), c.reporting_radius_m) for cam, c in zip(self._cameras, site.cameras)]
        self._grids = [CylinderGrid() if r is None else CylinderGrid(max_range_m=r) for r in reach]

    def project(self, message: Detections2D) -> CameraCylinders | None:
        if message.camera not in self.site.built_cameras:
            if message.camera not in self.unknown_cameras:
                log.warning("detections from camera %r, which site %r does not have; skipping them",
                            message.camera, self.site.site)
                self.unknown_cameras.add(message.camera)
            return None
        index = self.site.camera_index(message.camera)
        camera = self._cameras[index]
        cylinders = fit_cylinders(camera, message.to_boxes(), self.method, self._grids[index], camera_index=index)
        cylinders = cylinders[cylinders.near(camera.center, self.site.cameras[index].reporting_radius_m)]
        cylinders = with_position_covariance(cylinders, self._cameras)
        return CameraCylinders.from_cylinders(message.camera, message.seq, message.capture_ns, cylinders)


def main(args: argparse.Namespace) -> int:
    site, site_id = service_site(args)
    keys = bus.Keys(site_id)
    projector = Projector(site, args.method)
    stats = bus.BusStats()
    session = bus.open_session(bus.config_from_args(args))
    codec = bus.JsonCodec(CameraCylinders)
    publications = {cam: bus.Publication(session, keys.cylinders(cam), codec) for cam in site.camera_ids}
    inbox = bus.LatestSubscription(session, keys.detections("*"), bus.JsonCodec(Detections2D),
                                   keep=args.queue, stats=stats)
    token = bus.announce(session, keys, SERVICE)
    print(f"bevflow projector: site {site_id!r}, {len(site.camera_ids)} cameras, method {args.method}", flush=True)
    try:
        with stop_on_signals() as stop:
            while not stop.is_set():
                message = inbox.take(timeout=0.2)
                if message is None:
                    continue
                try:
                    result = projector.project(message)
                except Exception:  # a bug on one message must not stop the camera stream
                    stats.count("handler_errors")
                    log.exception("could not project detections %s/%d; skipping them", message.camera, message.seq)
                    continue
                if result is not None:
                    publications[result.camera].put(result)
    finally:
        token.undeclare()
        inbox.close()
        for publication in publications.values():
            publication.close()
        session.close()
    return 0
