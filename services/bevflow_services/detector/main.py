"""Find people in the cameras' frames and publish their 2D boxes, camera by camera.

    bevflow serve detector --site site.yaml
    bevflow serve detector --site site.yaml --cameras cam1,cam2 --threads 4

Subscribes to the frames of the site's cameras (or of ``--cameras``), runs ONNX Runtime on each
with the camera's model (``detector`` in the site file, or the model for its mounting height;
see ``bevflow_services.detector.models``) at the paper's height-adaptive scale, and publishes a
``Detections2D`` per frame with the frame's sequence number and capture time, in the pixels of
the camera's calibrated image (a frame sent smaller than its calibration, e.g. already at the
detector's scale, is mapped back). Only the window of the frame around the camera's reporting
radius is searched (``bevflow.detect.window``; ``--whole-frame`` searches it all): the projector
drops everyone outside it, and a demo-hall camera's window is 58 % of its frame.

Latest frame wins: each camera keeps only its newest unprocessed frame, and the workers take the
cameras whose frames have waited longest first (``bevflow_services.detector.schedule``), so a
detector slower than its cameras skips frames (counted) instead of falling behind; the skipped
sequence numbers show as dropped frames in the gateway's camera health. Bad frames (garbage
payloads, a size that does not fit the camera, undecodable JPEG) are logged, counted and skipped.

Workers: on the CPU, several frames each on one ONNX Runtime thread get more frames through than
one frame at a time on all the threads (6–20 % more on 2 cores: ``bevflow bench``,
``detector_workers_speedup_5_5m_2_cores``, ``docs/BENCHMARKS.md``): a small network's layers leave
a session's threads waiting on each other, and the Python around each inference runs on one core.
So by default there is a worker per usable core (at most one per camera), and the cores are shared
out among them as each inference's threads.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from bevflow.detect.providers import check_providers
from bevflow.camera import Camera
from bevflow.detect.runtime import SCORE_THRESHOLD, Detector, DetectorError
from bevflow.detect.still import StillFrames
from bevflow.detect.tiles import RimTileDetector
from bevflow.detect.window import detection_window, scaled_window
from bevflow.detections import Boxes
from bevflow.schemas import Detections2D, FrameHeader
from bevflow.site import Site

from bevflow_services import bus
from bevflow_services.detector.models import CameraModels
from bevflow_services.detector.schedule import ReadyCameras
from bevflow_services.runtime import UserError, service_site, stop_on_signals, usable_cores
from bevflow_services.service_metrics import MetricsBook, reporting

log = logging.getLogger(__name__)
SERVICE = "detector"
ASPECT_TOLERANCE = 0.02  # a frame whose width and height scale differently is not this camera's
REPORT_EVERY_S = 30.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("detector")
    group.add_argument("--cameras", default="", help="comma-separated camera ids to serve (default: all)")
    group.add_argument("--model", default=None, metavar="MODEL",
                       help="ONNX file or shipped model name for cameras whose site entry names none "
                       "(default: the shipped model for the camera's height)")
    group.add_argument("--workers", type=int, default=None, metavar="N",
                       help="frames detected at once, each camera's one at a time (default: one per usable CPU core, "
                       "at most one per camera)")
    group.add_argument("--threads", type=int, default=None, metavar="N",
                       help="ONNX Runtime threads per inference (default: the usable CPU cores shared among the "
                       "workers, at least 1)")
    group.add_argument("--score-threshold", type=float, default=None,
                       help="lowest confidence of a reported person, 0 to 1, for every model: each model file maps its "
                       "scores onto one scale (default: each model's own threshold, kept in its file, else "
                       f"{SCORE_THRESHOLD:g})")  # fmt: skip
    group.add_argument("--providers", default=None, metavar="LIST",
                       help="ONNX Runtime execution providers, most wanted first, e.g. cuda,cpu or openvino,cpu "
                       "(default: the site file's detector_providers, else cpu); missing ones fall back with a warning")
    group.add_argument("--skip-still", action="store_true",
                       help="reuse a camera's last boxes while its picture shows nothing new (a few thumbnail pixels "
                       "changed by under 10 grey levels; detected again at least every second): saves the detector's "
                       "time on empty or motionless cameras, costs about 0.5 ms a frame elsewhere")  # fmt: skip
    group.add_argument("--whole-frame", action="store_true",
                       help="run the detector on the whole frame, not only the part that shows the camera's "
                       "monitored radius (slower; finds people the projector then drops)")


class BadFrame(Exception):
    """A frame that cannot be run through the detector; ``reason`` is a short counter label."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = reason, detail


class FrameDetector:
    """The service's work, apart from the bus: one frame in, that camera's boxes out."""

    def __init__(self, site: Site, detectors: dict[str, Detector | RimTileDetector], whole_frame: bool = False,
                 still: StillFrames | None = None) -> None:  # fmt: skip
        self.site = site
        self.detectors = detectors
        # Each camera's window around its reporting radius; the rest of the frame holds nobody
        # the projector would keep (``bevflow.detect.window``).
        radius = {c.id: c.reporting_radius_m for c in site.cameras}
        self.windows = {c: None if whole_frame else detection_window(site.camera(c), radius[c]) for c in detectors}
        # With ``still``: a window that shows nothing new reuses that camera's last boxes.
        self.still = still
        self._last: dict[str, Detections2D] = {}
        self.reused: Counter[str] = Counter()

    def detect(self, header: FrameHeader, image: np.ndarray) -> Detections2D:
        """Boxes of the people in ``image`` (as its ``header`` describes it), in the camera's
        calibrated pixels; ``BadFrame`` for a frame that does not fit its camera."""
        camera_id = header.camera
        if camera_id not in self.detectors:
            raise BadFrame("unknown_camera", f"camera {camera_id!r} is not served here")
        bgr = _bgr(header, image)
        camera = self.site.camera(camera_id)
        width, height = camera.image_size
        sx, sy = bgr.shape[1] / width, bgr.shape[0] / height
        if abs(sx / sy - 1.0) > ASPECT_TOLERANCE:
            raise BadFrame("frame_size", f"a {bgr.shape[1]}x{bgr.shape[0]} frame from {camera_id}, "
                           f"whose calibration is {width}x{height}")
        x0, y0, x1, y1 = scaled_window(self.windows[camera_id], sx, bgr.shape[1], bgr.shape[0])
        window = bgr[y0:y1, x0:x1]
        last = self._last.get(camera_id)
        if self.still is not None and self.still.is_still(camera_id, window, header.capture_ns) and last is not None:
            self.reused[camera_id] += 1
            return last.model_copy(update={"seq": header.seq, "capture_ns": header.capture_ns})
        detector = self.detectors[camera_id]
        # A rotation-aware detector turns its tiles about the point people lie radially about.
        radial = {"centre": _nadir_in_window(camera, sx, sy, x0, y0)} if hasattr(detector, "detect_rotated") else {}
        boxes = detector.detect(window, float(camera.center[2]), float(camera.K[0, 0]) * sx, **radial)
        # Window pixels → frame pixels → calibrated pixels (pixel centres: u = (u' + 0.5) / s − 0.5).
        scale = np.array([sx, sy, sx, sy])
        xyxy = (boxes.xyxy + [x0, y0, x0, y0] + 0.5) / scale - 0.5
        result = Detections2D.from_boxes(camera_id, header.seq, header.capture_ns, Boxes(xyxy=xyxy, confidence=boxes.confidence))
        self._last[camera_id] = result
        return result


def _nadir_in_window(camera: Camera, sx: float, sy: float, x0: int, y0: int) -> tuple[float, float]:
    u, v = camera.nadir_pixel()
    return ((u + 0.5) * sx - 0.5 - x0, (v + 0.5) * sy - 0.5 - y0)


def _bgr(header: FrameHeader, image: np.ndarray) -> np.ndarray:
    if header.encoding == "jpeg":
        decoded = cv2.imdecode(np.asarray(image, dtype=np.uint8).reshape(-1), cv2.IMREAD_COLOR)
        if decoded is None:
            raise BadFrame("undecodable", f"frame {header.camera}/{header.seq} is not a readable JPEG")
        if decoded.shape[:2] != (header.height, header.width):
            raise BadFrame("frame_size", f"a {decoded.shape[1]}x{decoded.shape[0]} JPEG whose header says "
                           f"{header.width}x{header.height}")
        return decoded
    if header.encoding == "gray8":
        return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_GRAY2BGR)
    return np.asarray(image)


class _Inbox(bus.LatestSubscription[bus.Frame]):
    """A camera's newest frame; tells ``ready`` when one arrives."""

    def __init__(self, session, camera: str, key: str, stats: bus.BusStats, ready: ReadyCameras) -> None:
        self._camera, self._ready_cameras = camera, ready
        super().__init__(session, key, bus.FRAMES, keep=1, stats=stats)

    def _accept(self, sample) -> None:
        super()._accept(sample)
        self._ready_cameras.arrived(self._camera)


def main(args: argparse.Namespace) -> int:
    site, site_id = service_site(args)
    cameras = [c for c in args.cameras.split(",") if c] or site.camera_ids
    unknown = sorted(set(cameras) - set(site.camera_ids))
    if unknown:
        raise UserError(f"--cameras: site {site.site!r} has no camera {', '.join(unknown)}")
    if args.score_threshold is not None and not 0.0 <= args.score_threshold <= 1.0:
        raise UserError(f"--score-threshold must be between 0 and 1, got {args.score_threshold}")
    site_path = Path(args.site)
    site_dir = site_path.parent if site_path.is_file() else None
    try:
        providers = check_providers(args.providers.split(",")) if args.providers is not None else site.detector_providers
        workers, threads = share_cores(len(cameras), args.workers, args.threads, usable_cores())
        models = CameraModels(site, cameras, site_dir=site_dir, default=args.model, threads=threads,
                              score_threshold=args.score_threshold, providers=providers)
    except (DetectorError, ValueError) as exc:
        raise UserError(f"--providers: {exc}" if "provider" in str(exc) else str(exc)) from None
    worker = FrameDetector(site, models.detectors, whole_frame=args.whole_frame, still=StillFrames() if args.skip_still else None)
    keys = bus.Keys(site_id)
    stats = bus.BusStats()
    session = bus.open_session(bus.config_from_args(args))
    codec = bus.JsonCodec(Detections2D)
    ready = ReadyCameras()
    inboxes = {c: _Inbox(session, c, keys.frame(c), stats, ready) for c in cameras}
    publications = {c: bus.Publication(session, keys.detections(c), codec) for c in cameras}
    token = bus.announce(session, keys, SERVICE)
    print(f"bevflow detector: site {site_id!r}, {len(cameras)} cameras, models {models.models()}, "
          f"on {', '.join(models.providers())}, {workers} workers of {threads} threads", flush=True)
    try:
        book = MetricsBook()
        for camera, (model, provider) in models.runs_on().items():
            book.set("detector_model_info", 1.0, camera=camera, model=model, provider=provider)
        with stop_on_signals() as stop, reporting(session, site_id, SERVICE, book):
            serve(inboxes, publications, worker, stats, stop, ready, book, workers=workers)
    finally:
        token.undeclare()
        for inbox in inboxes.values():
            inbox.close()
        for publication in publications.values():
            publication.close()
        session.close()
    return 0


def share_cores(cameras: int, workers: int | None, threads: int | None, cores: int) -> tuple[int, int]:
    """(workers, ONNX Runtime threads per inference): those asked for, else a worker per core (at
    most one per camera, as a camera's frames are detected one at a time) and the cores shared
    out among them (module docstring, "Workers")."""
    for name, value in (("--workers", workers), ("--threads", threads)):
        if value is not None and value < 1:
            raise UserError(f"{name} must be at least 1, got {value}")
    chosen = workers if workers is not None else max(1, min(cores, cameras))
    return chosen, threads if threads is not None else max(1, cores // chosen)


def serve(inboxes: dict[str, _Inbox], publications: dict[str, bus.Publication[Detections2D]],
          worker: FrameDetector, stats: bus.BusStats, stop: threading.Event, ready: ReadyCameras,
          book: MetricsBook | None = None, workers: int = 1) -> None:
    """Serve the cameras that ``ready`` names, each its newest frame, on ``workers`` threads,
    until ``stop`` is set; ``book`` gets each frame's capture-to-published time. A worker that
    fails (not on a frame: those are counted and skipped) stops the others and is raised here."""
    service = _Workers(inboxes, publications, worker, stats, ready, book if book is not None else MetricsBook())
    threads = [threading.Thread(target=service.work, args=(stop,), name=f"detect-{i}") for i in range(workers)]
    for thread in threads:
        thread.start()
    try:
        while not stop.wait(REPORT_EVERY_S):
            log.info("frames detected %d; bus %s", service.detected, stats.snapshot())
    finally:
        stop.set()
        for thread in threads:
            thread.join()
    if service.failure is not None:
        raise service.failure


@dataclass
class _Workers:
    """What the worker threads share; each works on one camera's newest frame at a time."""

    inboxes: dict[str, _Inbox]
    publications: dict[str, bus.Publication[Detections2D]]
    detector: FrameDetector
    stats: bus.BusStats
    ready: ReadyCameras
    book: MetricsBook
    detected: int = 0
    failure: BaseException | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def work(self, stop: threading.Event) -> None:
        try:
            while not stop.is_set():
                camera = self.ready.claim(timeout=0.2)
                if camera is None:
                    continue
                try:
                    self._serve(camera)
                finally:
                    self.ready.release(camera)
        except BaseException as exc:
            self.failure = exc
            stop.set()

    def _serve(self, camera: str) -> None:
        # Published as soon as it is detected: the tracker closes a tick once every camera it
        # waits for has reported, and a camera held back for others only makes that later.
        inbox = self.inboxes[camera]
        frame = inbox.take(timeout=0)
        if frame is None:  # taken already, with an earlier claim
            return
        message = _detect_one(self.detector, self.stats, camera, inbox.key, frame)
        reused = self.detector.reused.pop(camera, 0)  # this camera's counter: only its worker touches it
        if reused:
            self.book.count("detector_frames_reused", reused, camera=camera)
        if message is None:
            return
        self.publications[camera].put(message)
        self.book.observe("detector_latency_seconds", max(0.0, (time.time_ns() - message.capture_ns) / 1e9))
        with self._lock:
            self.detected += 1


def _detect_one(worker: FrameDetector, stats: bus.BusStats, camera: str, key: str, frame: bus.Frame) -> Detections2D | None:
    """One camera's frame through the detector; None (counted and logged) for a frame that does
    not fit its camera or a bug, which must not stop the other cameras."""
    if frame.header.camera != camera:
        stats.reject(key, "wrong_camera", f"a frame of {frame.header.camera!r} on {camera}'s key")
        return None
    try:
        return worker.detect(frame.header, frame.image)
    except BadFrame as exc:
        stats.reject(key, exc.reason, exc.detail)
    except Exception:  # a bug on one frame must not stop the other cameras
        stats.count("handler_errors")
        log.exception("could not run the detector on %s/%d; skipping it", camera, frame.header.seq)
    return None
