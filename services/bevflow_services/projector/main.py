"""Turn each camera's 2D person boxes into world cylinders with that camera's calibration.

    bevflow serve projector --site site.yaml

Subscribes to every camera's detections of the site and publishes one ``CameraCylinders`` per
detections message. The fit is the paper's 3D cylinder estimation (``bevflow.cylinder``); its
per-camera lookup tables are built on a camera's first message. Each cylinder carries the
covariance of its feet position and, where its box measures it, the person's head height
(``bevflow.stature``). The work itself is ``bevflow.live.projection.CameraProjection``,
which a replay of recorded boxes runs too. Messages from cameras the site does not know are
counted and skipped, never fatal. Under overload the oldest detections are
dropped (counted), so what is published stays current.
"""

from __future__ import annotations

import argparse
import logging

from bevflow.cylinder import METHODS, projection_method
from bevflow.live.projection import CameraProjection
from bevflow.schemas import CameraCylinders, Detections2D
from bevflow.site import Site

from bevflow_services import bus
from bevflow_services.runtime import service_site, stop_on_signals

log = logging.getLogger(__name__)
SERVICE = "projector"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("projector")
    group.add_argument("--method", choices=METHODS, default="cylinder",
                       help="how a box becomes a floor position (default: the paper's cylinder fit)")
    group.add_argument("--queue", type=int, default=64,
                       help="detections kept waiting before the oldest are dropped (default 64)")


class Projector:
    """The service's work, apart from the bus: one detections message in, cylinders out
    (``bevflow.live.projection.CameraProjection``), cameras the site lacks skipped."""

    def __init__(self, site: Site, method: str = "cylinder") -> None:
        self.site = site
        self.method = method
        self.unknown_cameras: set[str] = set()
        self._projection = CameraProjection(site, projection_method(method))

    def project(self, message: Detections2D) -> CameraCylinders | None:
        if message.camera not in self.site.built_cameras:
            if message.camera not in self.unknown_cameras:
                log.warning("detections from camera %r, which site %r does not have; skipping them",
                            message.camera, self.site.site)
                self.unknown_cameras.add(message.camera)
            return None
        cylinders = self._projection.project(message.camera, message.to_boxes())
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
