"""``bevflow demo``: the whole system on this machine, with no configuration."""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bevflow_services.runtime import UserError


# Each rendered camera frame costs about 20 ms to render and 25-40 ms to detect on one core, so
# 2 cores sustain about 2 frames per second for each of the demo hall's 9 cameras. Rendering
# faster only renders frames the detector then skips.
RENDERED_CAMERA_FPS = 2.0
REPLAY_FPS = 4.0  # --detections without --fps: a guess (CMC's rate); a recording's own rate belongs in --fps


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo",
        help="run the live demo: a simulated hall, every service, the dashboard",
        description=(
            "Start every bevflow service on this machine over Zenoh on loopback: a built-in hall "
            "with nine ceiling fisheye cameras watching a simulated crowd (their frames rendered and "
            "run through the person detector), the tracker, the history recorder, the REST API, "
            "the dashboard and the 3D view. Stop with Ctrl-C."
        ),
    )
    parser.add_argument("--port", type=int, default=8000, help="dashboard and API port (default 8000; the 3D view uses the next one)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: run until Ctrl-C)")
    parser.add_argument("--site", default="demo-hall", help="site file or built-in site name (default demo-hall)")
    parser.add_argument("--people", type=int, default=None, help="people in the hall at once (default: the site's preset)")
    parser.add_argument("--boxes", choices=("rendered", "simulated"), default="rendered",
                        help="rendered: render the cameras' frames and run the detector on them (default); "
                        "simulated: the simulator reports noisy boxes directly (much lighter, no detector)")
    parser.add_argument("--camera-fps", type=float, default=None,
                        help=f"rendered frames per second per camera (default {RENDERED_CAMERA_FPS:g}: what the detector "
                        "keeps up with for the demo hall's 9 cameras on a 2-core machine; raise it on a bigger one)")
    parser.add_argument("--detections", type=Path, metavar="DIR",
                        help="show a recording instead of the simulated hall: DIR/<camera id>.txt holds each camera's "
                        "boxes (MOTChallenge rows frame,id,left,top,width,height,confidence,...) for the cameras of --site, "
                        "played in a loop; no detector runs (--boxes, --people and --camera-fps do not apply)")
    parser.add_argument("--fps", type=float, default=None, metavar="F",
                        help=f"--detections: the recording's frames per second (default {REPLAY_FPS:g})")
    parser.add_argument("--history-db", default=None, metavar="URL",
                        help="history database the recorder writes and the dashboard reads (a SQLite file or "
                        "postgresql:// URL; default: a new SQLite file in the log folder)")
    parser.add_argument("--no-history-db", action="store_true",
                        help="run without the recorder; the gateway keeps the last hour in memory")
    parser.add_argument("--log-dir", type=Path, default=None, help="where the services write their logs (default: a new temporary folder)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bevflow_services import extras
    from bevflow_services.launcher import TEMPORARY_DB, ServiceGroup, port_free, start_pipeline

    extras.require("services")  # here, not as each service it starts fails on its own
    boxes, ingest_args = _boxes(args)
    if boxes == "rendered":
        extras.require(extras.RUNTIME_EXTRAS[0])  # the detector's ONNX Runtime, any build
    for port in (args.port, args.port + 1):
        if not port_free(port):
            raise UserError(f"port {port} is already in use; choose another with --port")
    if args.no_history_db and args.history_db:
        raise UserError("--history-db and --no-history-db contradict each other; give one of them")
    history_db = None if args.no_history_db else (args.history_db or TEMPORARY_DB)
    log_dir = args.log_dir or Path(tempfile.mkdtemp(prefix="bevflow-demo-"))
    with ServiceGroup(site=args.site, log_dir=log_dir) as group:
        try:
            base = start_pipeline(group, args.port, boxes=boxes, history_db=history_db, ingest_args=ingest_args)
        except RuntimeError as exc:
            raise UserError(f"the demo could not start: {exc}\n(logs in {log_dir})") from None
        how = {"rendered": "rendered frames through the detector", "simulated": "simulated boxes",
               "replayed": f"the boxes recorded in {args.detections}"}[boxes]
        print(f"bevflow demo is running ({len(group.children)} services, {how}, logs in {log_dir})")
        print(f"  dashboard  {base}/")
        view3d = f"{base}/view3d/" if extras.missing_module("view3d") is None else f"off: it {extras.install_hint('view3d')}"
        print(f"  3D view    {view3d}")
        print(f"  REST API   {base}/docs")
        print("Stop with Ctrl-C." if args.duration is None else f"Stopping after {args.duration:g} s.", flush=True)
        deadline = None if args.duration is None else time.monotonic() + args.duration
        while deadline is None or time.monotonic() < deadline:
            dead = group.dead()
            if dead:
                child = dead[0]
                raise UserError(f"{child.name} stopped (exit code {child.process.returncode}):\n{child.log_tail()}")
            time.sleep(0.5)
    print("bevflow demo stopped")
    return 0


def _boxes(args: argparse.Namespace) -> tuple[str, tuple[str, ...]]:
    """Where the people come from (``launcher.start_pipeline``'s ``boxes``) and the ingest's options."""
    if args.detections is not None:
        if args.people is not None or args.camera_fps is not None:
            raise UserError("--people and --camera-fps shape the simulated hall; a --detections recording has its own")
        if not args.detections.is_dir():
            raise UserError(f"--detections {args.detections}: no such folder (expected one <camera id>.txt per camera)")
        fps = REPLAY_FPS if args.fps is None else args.fps
        if not fps > 0:
            raise UserError(f"--fps must be a number of frames per second > 0, got {args.fps}")
        return "replayed", ("--detections", str(args.detections.resolve()), "--fps", str(fps), "--loop")
    if args.fps is not None:
        raise UserError("--fps is the frame rate of a --detections recording")
    ingest_args: tuple[str, ...] = ("--people", str(args.people)) if args.people is not None else ()
    if args.boxes == "rendered":
        return "rendered", (*ingest_args, "--camera-fps", str(args.camera_fps or RENDERED_CAMERA_FPS))
    if args.camera_fps is not None:
        raise UserError("--camera-fps sets the rate of rendered frames; it has no effect with --boxes simulated")
    return "simulated", ingest_args
