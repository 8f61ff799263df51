"""Read the site's cameras and publish what they see.

    bevflow serve ingest --site site.yaml                 # cameras with a `source` in the site file
    bevflow serve ingest --site demo-hall --simulate      # the simulator's boxes (no detector)
    bevflow serve ingest --site demo-hall --simulate --render   # rendered frames, for the detector
    bevflow serve ingest --site site.yaml --detections DIR --fps 4   # a recording of boxes (no detector)

Real cameras: each camera's ``source`` (RTSP/HTTP URL, video file or image folder) is read on
its own thread (through FFmpeg, ``sources``) and its newest frame published with its capture time
(from the stream's own timestamps) and sequence number; a video file plays at its own frame rate.
A camera that drops, or stalls for ``--read-timeout``, is reopened with backoff and the others go
on; its frames stop meanwhile, which is how camera health (the tracker's ``camera_down``, the
gateway's ``/api/cameras``) sees it. A slow network gets the latest frame, not a backlog: frames
not yet sent are overwritten (counted).

Simulation: a crowd walks through the site in real time, and the simulator's ground truth is
published for scoring. With ``--render`` every camera's view is rendered through its own fisheye
model at the detector's input scale and published as a frame (capture time, sequence number =
the scene's frame number), for the detector service to find the people in. Without it every
camera reports the boxes of the people it sees, through the detector-noise model, straight onto
the detections key (the stage a detector would fill). If the machine cannot keep up, late frames
are skipped at the source and counted, never queued.

Recorded boxes (``--detections``, ``bevflow_services.ingest.replay``): a detector's boxes from
files, one per camera, published in real time as the cameras' detections.
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Iterator
from pathlib import Path

from bevflow.datasets.mot import MIN_CONFIDENCE
from bevflow.schemas import Detections2D, FrameHeader, SimulatedTruth
from bevflow.sim.feed import LIVE_NOISE, SimulatedFeed, scene_for_site
from bevflow.sim.noise import DetectorNoise
from bevflow.sim.render_feed import RenderedCameras
from bevflow.sim.render_textures import Appearance
from bevflow.sim.scene import SceneFrame
from bevflow.sim.views import GroundTruth
from bevflow.site import Site

from bevflow_services import bus
from bevflow_services.ingest import replay
from bevflow_services.ingest.sources import LatestFrameReader, Timeouts
from bevflow_services.runtime import UserError, service_site, stop_on_signals

log = logging.getLogger(__name__)
SERVICE = "ingest"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("ingest")
    group.add_argument("--simulate", action="store_true",
                       help="simulate a crowd and the cameras' detections instead of reading the cameras")
    group.add_argument("--render", action="store_true",
                       help="simulation: publish rendered frames (for the detector service) instead of boxes")
    group.add_argument("--cameras", default="", help="comma-separated camera ids to serve (default: all)")
    group.add_argument("--people", type=int, default=None, help="simulation: people on the floor at once")
    group.add_argument("--seed", type=int, default=0, help="simulation: random seed")
    group.add_argument("--jitter", type=float, default=LIVE_NOISE.jitter, help="simulation: box edge noise")
    group.add_argument("--drop", type=float, default=LIVE_NOISE.drop, help="simulation: missed detections")
    group.add_argument("--false-positives", type=float, default=LIVE_NOISE.false_positives,
                       help="simulation: spurious boxes per camera per frame")
    group.add_argument("--camera-fps", type=float, default=None,
                       help="simulation with --render: frames per second each camera publishes (default: the "
                       "scene's rate, 10); lower it when the detector cannot keep up with every camera")
    group.add_argument("--folder-fps", type=float, default=10.0, help="frame rate of image-folder sources")
    group.add_argument("--open-timeout", type=float, default=Timeouts.open_s, metavar="S",
                       help=f"seconds a camera stream may take to open before it is retried (default {Timeouts.open_s:g})")
    group.add_argument("--read-timeout", type=float, default=Timeouts.read_s, metavar="S",
                       help=f"seconds without data after which an open stream counts as broken and is reopened "
                       f"(default {Timeouts.read_s:g}; keep it under the tracker's --camera-timeout)")
    group.add_argument("--detections", type=Path, metavar="DIR",
                       help="publish a recording of a detector's boxes instead of reading the cameras: DIR/<camera id>.txt "
                       "with MOTChallenge rows frame,id,left,top,width,height,confidence,... (no detector needed)")
    group.add_argument("--fps", type=float, metavar="F", help="--detections: frames per second of the recording")
    group.add_argument("--min-confidence", type=float, default=MIN_CONFIDENCE, metavar="C",
                       help=f"--detections: publish boxes of confidence C or more (default {MIN_CONFIDENCE:g})")
    group.add_argument("--loop", action="store_true", help="--detections: start the recording again when it ends")


def main(args: argparse.Namespace) -> int:
    site, site_id = service_site(args)
    if args.render and not args.simulate:
        raise UserError("--render renders the simulator's frames; use it with --simulate")
    if args.camera_fps is not None and not args.render:
        raise UserError("--camera-fps sets the rate of rendered frames; use it with --simulate --render")
    cameras = [c for c in args.cameras.split(",") if c] or site.camera_ids
    unknown = sorted(set(cameras) - set(site.camera_ids))
    if unknown:
        raise UserError(f"--cameras: site {site.site!r} has no camera {', '.join(unknown)}")
    if args.detections is not None and args.simulate:
        raise UserError("--detections publishes recorded boxes; --simulate makes up its own: give one of them")
    recording = replay.load_recording(args, site, cameras) if args.detections is not None else None
    session = bus.open_session(bus.config_from_args(args))
    keys = bus.Keys(site_id)
    token = bus.announce(session, keys, SERVICE)
    try:
        with stop_on_signals() as stop:
            if recording is not None:
                replay.replay(session, keys, recording, args, stop)
            elif args.simulate and args.render:
                simulate_frames(session, keys, site, cameras, args, stop)
            elif args.simulate:
                noise = DetectorNoise(jitter=args.jitter, drop=args.drop, false_positives=args.false_positives)
                simulate(session, keys, site, cameras, noise, args, stop)
            else:
                stream(session, keys, site, cameras, args, stop)
    finally:
        token.undeclare()
        session.close()
    return 0


def simulate(session, keys: bus.Keys, site: Site, cameras: list[str], noise: DetectorNoise,
             args: argparse.Namespace, stop) -> None:
    feed = SimulatedFeed(scene_for_site(site, people=args.people, seed=args.seed), noise, seed=args.seed)
    codec = bus.JsonCodec(Detections2D)
    publications = {c: bus.Publication(session, keys.detections(c), codec) for c in cameras}
    truth_out = bus.Publication(session, keys.truth, bus.JsonCodec(SimulatedTruth))
    print(f"bevflow ingest: simulating {len(cameras)} cameras of {site.site!r} at {feed.fps:g} fps", flush=True)
    for scene_frame, truth in in_real_time(feed, stop, "simulation"):
        frame = feed.observe(scene_frame, truth)
        capture_ns = time.time_ns()
        for camera in cameras:
            boxes = frame.detections[site.camera_index(camera)]
            publications[camera].put(Detections2D.from_boxes(camera, frame.index, capture_ns, boxes))
        truth_out.put(simulated_truth(site, frame.index, capture_ns, truth))
    for publication in publications.values():
        publication.close()
    truth_out.close()


def simulate_frames(session, keys: bus.Keys, site: Site, cameras: list[str], args: argparse.Namespace,
                    stop) -> None:
    """Render every camera's view of the simulated crowd at the scene's frame rate and publish
    the frames; late scene frames are skipped whole (every camera), so cameras stay in step."""
    feed = SimulatedFeed(scene_for_site(site, people=args.people, seed=args.seed), seed=args.seed)
    renderers = RenderedCameras(site, feed.preset.scene, cameras, seed=args.seed)
    publications = {c: bus.Publication(session, keys.frame(c), bus.FRAMES) for c in cameras}
    truth_out = bus.Publication(session, keys.truth, bus.JsonCodec(SimulatedTruth))
    sizes = {c: renderers.frame_size(c) for c in cameras}
    every = camera_frame_stride(feed.fps, args.camera_fps)
    shown = ", ".join(f"{c} {w}x{h}" for c, (w, h) in sizes.items())
    print(f"bevflow ingest: rendering {len(cameras)} cameras of {site.site!r} at {feed.fps / every:g} fps ({shown})",
          flush=True)
    for scene_frame, truth in in_real_time(feed, stop, "rendering", every):
        # The capture time is when the scene looked like this; rendering is the camera's readout.
        capture_ns = time.time_ns()
        bodies = scene_frame.primitives()
        appearance = Appearance.for_identities(scene_frame.identity, args.seed)
        images = {camera: renderers.render(camera, scene_frame, bodies, appearance).image for camera in cameras}
        # All cameras' frames of this instant go out together, so a detector that takes every
        # camera's newest frame gets frames of one instant.
        for camera, image in images.items():
            w, h = sizes[camera]
            header = FrameHeader(camera=camera, seq=scene_frame.index // every, capture_ns=capture_ns, width=w, height=h)
            publications[camera].put(bus.Frame(header, image))
        truth_out.put(simulated_truth(site, scene_frame.index // every, capture_ns, truth))
    for publication in publications.values():
        publication.close()
    truth_out.close()


def in_real_time(feed: SimulatedFeed, stop, what: str, every: int = 1) -> Iterator[tuple[SceneFrame, GroundTruth]]:
    """Every ``every``-th scene frame of ``feed`` and its truth, each when its time comes; a frame
    whose time has passed by a whole period is skipped (dropped at the source, never queued)."""
    period_ns = int(1e9 / feed.fps)
    start_ns = time.time_ns()
    skipped = 0
    for scene_frame, truth in feed.scene_frames():
        if scene_frame.index % every:  # the crowd moves on between the frames the cameras take
            continue
        due_ns = start_ns + scene_frame.index * period_ns
        if stop.wait(max(0.0, (due_ns - time.time_ns()) / 1e9)):
            return
        if time.time_ns() - due_ns > period_ns:
            skipped += 1
            if skipped % 100 == 1:
                log.warning("%s behind real time; %d frames skipped so far", what, skipped)
            continue
        yield scene_frame, truth


def simulated_truth(site: Site, frame: int, capture_ns: int, truth: GroundTruth) -> SimulatedTruth:
    return SimulatedTruth(site=site.site, frame=frame, capture_ns=capture_ns, tracks=truth.track_ids.tolist(),
                          positions=[(float(x), float(y)) for x, y in truth.feet_xy])


def camera_frame_stride(scene_fps: float, camera_fps: float | None) -> int:
    """Publish every n-th scene frame so each camera runs at about ``camera_fps``."""
    if camera_fps is None:
        return 1
    if not 0 < camera_fps <= scene_fps:
        raise UserError(f"--camera-fps must be above 0 and at most the scene's {scene_fps:g} fps, got {camera_fps:g}")
    return max(1, round(scene_fps / camera_fps))


def stream_timeouts(args: argparse.Namespace) -> Timeouts:
    if args.open_timeout <= 0 or args.read_timeout <= 0:
        raise UserError(f"--open-timeout and --read-timeout must be above 0, got {args.open_timeout:g} "
                        f"and {args.read_timeout:g}")
    return Timeouts(open_s=args.open_timeout, read_s=args.read_timeout)


def stream(session, keys: bus.Keys, site: Site, cameras: list[str], args: argparse.Namespace, stop) -> None:
    configured = {c.id: c.source for c in site.cameras if c.id in cameras}
    missing = sorted(c for c, s in configured.items() if not s)
    if missing:
        raise UserError(f"cameras {', '.join(missing)} have no 'source' in the site file; "
                        "give each a stream URL, video file or image folder, or run with --simulate")
    sources = {c: s for c, s in configured.items() if s}
    timeouts = stream_timeouts(args)
    readers = {c: LatestFrameReader(s, folder_fps=args.folder_fps, timeouts=timeouts).start()
               for c, s in sources.items()}
    publications = {c: bus.Publication(session, keys.frame(c), bus.FRAMES) for c in cameras}
    print(f"bevflow ingest: reading {len(cameras)} cameras of {site.site!r}", flush=True)
    while not stop.is_set():
        idle = True
        for camera, reader in readers.items():
            frame = reader.take(timeout=0.0)
            if frame is None:
                continue
            idle = False
            h, w = frame.image.shape[:2]
            header = FrameHeader(camera=camera, seq=frame.seq, capture_ns=frame.capture_ns, width=w, height=h)
            publications[camera].put(bus.Frame(header, frame.image))
        if idle:
            stop.wait(0.005)
    for reader in readers.values():
        reader.stop()
    for publication in publications.values():
        publication.close()
