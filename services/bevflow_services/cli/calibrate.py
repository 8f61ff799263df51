"""``bevflow calibrate``: a camera's lens, its pose, and whether overlapping cameras agree.

Three steps, in the order a technician runs them on a new site:

- ``intrinsics``: chessboard pictures (a folder or a video) -> K and D of one camera;
- ``extrinsics``: image <-> floor points of one camera -> where it hangs and how it is turned;
- ``check``: people seen by two cameras at once -> how far apart the two cameras put them.

The first two write their result into the site file, changing only that camera's lines (the old
file is kept as ``<site>.bak``). Every step prints what it did and what to do next.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
from pydantic import ValidationError

from bevflow.calibration.chessboard import Chessboard
from bevflow.calibration.consistency import PairConsistency, check_consistency, format_consistency
from bevflow.calibration.extrinsics import (
    CHECKABLE_POINTS,
    ExtrinsicsError,
    PoseFit,
    check_fit,
    estimate_pose,
    load_correspondences,
)
from bevflow.calibration.intrinsics import (
    RECOMMENDED_ANGLE_DEG,
    RECOMMENDED_VIEWS,
    BoardView,
    CalibrationError,
    IntrinsicsResult,
    calibrate_intrinsics,
)
from bevflow.calibration.sources import dataset_source, message_source, simulated_source
from bevflow.schemas import CameraCylinders
from bevflow.site import CameraConfig, Site, SiteError, Thresholds, load_site, load_site_or_builtin
from bevflow.site_edit import update_camera_file

from bevflow_services.bus_flags import add_bus_arguments
from bevflow_services.runtime import UserError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")

EPILOG = """\
steps (see docs/INSTALL.md):
  bevflow calibrate intrinsics --camera hall-sw --site site.yaml --images shots/hall-sw --board 9x6 --square 0.025
  bevflow calibrate extrinsics --camera hall-sw --site site.yaml --points marks/hall-sw.csv
  bevflow calibrate check --site site.yaml --live 120 --connect tcp/ROUTER:7447   (the running system)
  bevflow calibrate check --dataset wildtrack --root /data/Wildtrack
  bevflow calibrate check --sim demo-hall --site my-demo-hall.yaml                (a calibration against a simulation)

Exit status: 0 on success, 2 for a usage or input error or a refused calibration (message on stderr)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="calibrate a camera's lens and pose into the site file, and check overlapping cameras",
        description="Calibrate one camera at a time (lens, then pose) and check that overlapping cameras agree.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    steps = parser.add_subparsers(dest="step", metavar="STEP", required=True)
    _register_intrinsics(steps)
    _register_extrinsics(steps)
    _register_check(steps)


# --- intrinsics -----------------------------------------------------------------------------------
def _register_intrinsics(steps: argparse._SubParsersAction) -> None:
    p = steps.add_parser(
        "intrinsics",
        help="the lens (K, D) from chessboard pictures",
        description="Find a chessboard in pictures taken with the camera, calibrate its lens and write K and D "
        "into the site file. Take 12 or more pictures with the whole board in view: near the centre, near "
        "every edge of the picture, tilted different ways.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--images", type=Path, metavar="DIR", help="a folder of pictures (png, jpg, bmp, tif)")
    source.add_argument("--video", type=Path, metavar="FILE", help="a video of the board moving in front of the camera")
    p.add_argument("--board", required=True, metavar="COLSxROWS", help="inner corners of the board, e.g. 9x6 for a board of 10 x 7 squares")
    p.add_argument("--square", required=True, type=float, metavar="METRES", help="side of one square in metres, e.g. 0.025")
    p.add_argument("--model", choices=("fisheye", "pinhole"), help="lens model (default: the camera's model in the site file)")
    p.add_argument("--camera", required=True, metavar="ID", help="the camera's id in the site file")
    p.add_argument("--site", required=True, type=Path, metavar="SITE", help="the site file to update")
    p.add_argument("--max-views", type=int, default=40, metavar="N", help="use at most N frames of a video, evenly spread (default 40)")
    p.add_argument("--max-rms", type=float, default=1.0, metavar="PX", help="refuse a calibration whose RMS error is above PX pixels (default 1.0)")
    p.add_argument("--dry-run", action="store_true", help="calibrate and print, but do not change the site file")
    p.set_defaults(func=run_intrinsics)


def run_intrinsics(args: argparse.Namespace) -> int:
    site = _load_site_file(args.site)
    config = _camera_config(site, args.camera, args.site)
    model = args.model or config.model
    try:
        board = Chessboard.parse(args.board, args.square)
    except ValueError as exc:
        raise UserError(f"--board/--square: {exc}") from None
    frames = list(_read_images(args.images) if args.images is not None else _read_video(args.video, args.max_views))
    size = _common_size(frames)
    views = []
    print(f"looking for a {board.cols}x{board.rows} board in {len(frames)} pictures:")
    for name, image in frames:
        corners = board.find_corners(image)
        print(f"  {name:<32} {'found' if corners is not None else 'no board'}")
        views.append(BoardView(name, corners if corners is not None else np.zeros((0, 2))))
    try:
        result = calibrate_intrinsics(views, board, size, model=model)
    except CalibrationError as exc:
        raise UserError(str(exc)) from None
    print(_intrinsics_report(result))
    if result.rms_px > args.max_rms:
        raise UserError(
            f"calibration refused: RMS error {result.rms_px:.2f} px is above --max-rms {args.max_rms:g}; check --board and "
            "--square, and use sharp pictures of a flat board"
        )
    changes: dict[str, object] = {"model": model} if model != config.model else {}
    changes |= {
        "image_size": [int(size[0]), int(size[1])],
        "intrinsics": {"fx": float(result.K[0, 0]), "fy": float(result.K[1, 1]), "cx": float(result.K[0, 2]), "cy": float(result.K[1, 2])},
        "distortion": [float(v) for v in result.dist],
    }
    if size != tuple(config.image_size):
        print(f"note: the pictures are {size[0]}x{size[1]}, the site file said {config.image_size[0]}x{config.image_size[1]}; "
              "image_size is updated too (the camera's stream must have this size)")
    _save(args, changes, "K and D")
    print(f"next: mark at least {CHECKABLE_POINTS} floor points in a still frame of {args.camera} and run\n"
          f"  bevflow calibrate extrinsics --camera {args.camera} --site {args.site} --points POINTS.csv\n"
          f"  (or click them on the dashboard's calibration page, /calibration.html, with the gateway serving --site {args.site})")
    return 0


def _intrinsics_report(result: IntrinsicsResult) -> str:
    lines = ["", f"{'view':<32} {'RMS px':>7}"]
    lines += [f"{name:<32} {rms:>7.3f}" for name, rms in result.view_rms_px.items()]
    lines += [f"{name:<32} dropped: {reason}" for name, reason in result.dropped]
    K = result.K
    lines += [
        "",
        f"{result.model} lens from {len(result.view_rms_px)} views: RMS {result.rms_px:.3f} px",
        f"  fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f}",
        f"  distortion {', '.join(f'{v:.6g}' for v in result.dist)}",
        f"  the board reached {result.max_angle_deg:.0f} degrees off the optical axis",
    ]
    if len(result.view_rms_px) < RECOMMENDED_VIEWS:
        lines.append(f"warning: only {len(result.view_rms_px)} views used; {RECOMMENDED_VIEWS} or more give a steadier lens")
    if math.isfinite(result.max_angle_deg) and result.max_angle_deg < RECOMMENDED_ANGLE_DEG:
        lines.append(f"warning: the lens is only known to {result.max_angle_deg:.0f} degrees off axis; ceiling cameras see "
                     f"people out to {RECOMMENDED_ANGLE_DEG:.0f} degrees and more: add pictures with the board near the edge")
    return "\n".join(lines)


def _read_images(folder: Path) -> Iterator[tuple[str, np.ndarray]]:
    if not folder.is_dir():
        raise UserError(f"--images {folder}: no such folder")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise UserError(f"--images {folder}: no pictures ({', '.join(IMAGE_SUFFIXES)}) in the folder")
    for path in paths:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise UserError(f"{path}: not a readable picture")
        yield path.name, image


def _read_video(path: Path, max_views: int) -> Iterator[tuple[str, np.ndarray]]:
    if max_views < 1:
        raise UserError(f"--max-views must be at least 1, got {max_views}")
    capture = cv2.VideoCapture(str(path))
    if not path.is_file() or not capture.isOpened():
        raise UserError(f"--video {path}: not a readable video file")
    try:
        total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        wanted = set(np.linspace(0, max(total - 1, 0), min(max_views, max(total, 1))).round().astype(int).tolist())
        index = 0
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            if index in wanted or total <= 0:
                yield f"frame {index}", cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            index += 1
    finally:
        capture.release()
    if index == 0:
        raise UserError(f"--video {path}: no frames could be read")


def _common_size(frames: list[tuple[str, np.ndarray]]) -> tuple[int, int]:
    sizes = {(img.shape[1], img.shape[0]) for _, img in frames}
    if len(sizes) > 1:
        listed = ", ".join(f"{w}x{h}" for w, h in sorted(sizes))
        raise UserError(f"the pictures have different sizes ({listed}); calibrate with pictures of one camera at one resolution")
    return sizes.pop()


# --- extrinsics -----------------------------------------------------------------------------------
def _register_extrinsics(steps: argparse._SubParsersAction) -> None:
    p = steps.add_parser(
        "extrinsics",
        help="where the camera hangs, from image <-> floor points",
        description="Estimate the camera's pose from points whose pixel and floor position are known, report each "
        "point's error, and write the pose into the site file (as extrinsics: rvec, tvec). The lens must be "
        "calibrated first.",
        epilog="points file: CSV with a header 'name,u,v,x,y,z' (u, v pixels; x, y, z metres, z may be left out for "
        "the floor), or YAML 'points: [{name, pixel: [u, v], world: [x, y, z]}]'. Use 6 or more points spread over "
        "the whole view.",
    )
    p.add_argument("--camera", required=True, metavar="ID", help="the camera's id in the site file")
    p.add_argument("--points", required=True, type=Path, metavar="FILE", help="the points file (.csv or .yaml)")
    p.add_argument("--site", required=True, type=Path, metavar="SITE", help="the site file to update")
    p.add_argument("--max-rms-px", type=float, default=3.0, metavar="PX", help="refuse a pose whose RMS reprojection error is above PX (default 3)")
    p.add_argument("--max-ground-error", type=float, default=0.15, metavar="M", help="refuse a pose that puts any point more than M metres off (default 0.15)")
    p.add_argument("--dry-run", action="store_true", help="estimate and print, but do not change the site file")
    p.set_defaults(func=run_extrinsics)


def run_extrinsics(args: argparse.Namespace) -> int:
    site = _load_site_file(args.site)
    camera = site.camera(_camera_config(site, args.camera, args.site).id)
    try:
        points = load_correspondences(args.points)
        fit = estimate_pose(camera, points)
    except ExtrinsicsError as exc:
        raise UserError(str(exc)) from None
    print(_extrinsics_report(fit))
    try:
        check_fit(fit, args.max_rms_px, args.max_ground_error)
    except ExtrinsicsError as exc:
        raise UserError(str(exc)) from None
    changes = {"pose": None, "extrinsics": {"rvec": [float(v) for v in fit.rvec], "tvec": [float(v) for v in fit.t]}}
    _save(args, changes, "the pose")
    print(_next_after_extrinsics(site, args.camera, args.site))
    return 0


def _next_after_extrinsics(site: Site, camera_id: str, path: Path) -> str:
    """The step after one camera's pose: the cameras still on their planned pose, or the check."""
    planned = [c.id for c in site.cameras if c.id != camera_id and c.pose is not None]
    if planned:
        shown = ", ".join(planned[:6]) + (f" and {len(planned) - 6} more" if len(planned) > 6 else "")
        return (f"next: {len(planned)} camera(s) still hang at their planned pose ({shown}); calibrate the next one, "
                "its lens first if not done yet:\n"
                f"  bevflow calibrate intrinsics --camera {planned[0]} --site {path} --images SHOTS_DIR --board 9x6 --square 0.025\n"
                f"  bevflow calibrate extrinsics --camera {planned[0]} --site {path} --points POINTS.csv\n"
                "then start the system and check that overlapping cameras agree (docs/INSTALL.md, steps 5 and 6)")
    if len(site.cameras) > 1:
        return ("next: every camera is calibrated; start the system with this site (docs/INSTALL.md, step 6), let people walk "
                f"through the overlaps, and check that overlapping cameras agree:\n  bevflow calibrate check --site {path} --live 120")
    return f"next: start the system with this site: bevflow serve ... --site {path} (docs/INSTALL.md, step 6)"


def _extrinsics_report(fit: PoseFit) -> str:
    p = fit.points
    lines = [f"{'point':<16} {'u':>8} {'v':>8} {'x m':>8} {'y m':>8} {'z m':>6} {'reproj px':>10} {'ground m':>9}"]
    for k, name in enumerate(p.names):
        (u, v), (x, y, z) = p.pixels[k], p.world[k]
        lines.append(f"{name:<16} {u:>8.1f} {v:>8.1f} {x:>8.3f} {y:>8.3f} {z:>6.2f} {fit.reprojection_px[k]:>10.2f} {fit.ground_error_m[k]:>9.3f}")
    c = fit.center
    lines += [
        "",
        f"camera centre ({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}) m, tilted {fit.tilt_deg:.2f} degrees from straight down",
        f"RMS reprojection {fit.rms_px:.2f} px, RMS ground error {fit.rms_ground_m:.3f} m over {len(p)} points",
    ]
    if len(p) < CHECKABLE_POINTS:
        lines.append(f"warning: with fewer than {CHECKABLE_POINTS} points a wrong point hardly shows in the errors; add more")
    return "\n".join(lines)


# --- check ----------------------------------------------------------------------------------------
def _register_check(steps: argparse._SubParsersAction) -> None:
    p = steps.add_parser(
        "check",
        help="do overlapping cameras put the same person in the same place?",
        description="Project people seen by two cameras at once with the site's calibration and report, per camera "
        "pair, the median offset between the two estimates and its spread, in metres.",
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--dataset", choices=("wildtrack",), help="annotated recordings read from --root")
    source.add_argument("--sim", metavar="PRESET", help="a simulated crowd: demo-hall or seq1..seq7; --site is the calibration to check (default: the preset's own)")
    source.add_argument("--live", type=float, metavar="SECONDS", help="listen this long to the running system's projectors (the site file's cameras)")
    source.add_argument("--cylinders", type=Path, metavar="FILE", help="a recording of the projectors' output: one CameraCylinders JSON message per line (see --save)")
    p.add_argument("--root", type=Path, metavar="DIR", help="the dataset folder")
    p.add_argument("--site", metavar="SITE", help="site file or built-in site name; for a dataset, default: the dataset's own calibration")
    p.add_argument("--frames", type=int, metavar="N", help="use at most N frames or ticks (default: all; a simulation: 100)")
    p.add_argument("--save", type=Path, metavar="FILE", help="with --live: also keep what was heard, for --cylinders")
    p.add_argument("--gate", type=float, default=1.0, metavar="M", help="how far apart two cameras' estimates of one person may be (default 1.0)")
    p.add_argument("--pairing", choices=("isolated", "fusion"), default="isolated",
                   help="isolated: only people alone in an overlap (default); fusion: what fusion merges at --gate")
    p.add_argument("--min-samples", type=int, default=20, metavar="N", help="judge only pairs with at least N samples, a sample being one person seen by both cameras in one frame (default 20)")
    p.add_argument("--tolerance", type=float, metavar="M", help="flag pairs whose median offset is above M (default: the site's fusion distance)")
    add_bus_arguments(p)
    p.set_defaults(func=run_check)


def run_check(args: argparse.Namespace) -> int:
    if (args.frames is not None and args.frames < 1) or not args.gate > 0:
        raise UserError("--frames must be at least 1 and --gate above 0")
    site = _load_any_site(args.site) if args.site is not None else None
    try:
        if args.dataset is not None:
            source = dataset_source(_load_dataset(args), site, args.frames)
        elif args.sim is not None:
            source = simulated_source(args.sim, site, args.frames or 100)
        else:
            if site is None:
                raise UserError(f"--{'live' if args.live is not None else 'cylinders'} needs --site (the calibration the cameras are projected with)")
            messages = _listen(site, args) if args.live is not None else _read_messages(args.cylinders)
            source = message_source(site, messages, frames=args.frames)
            print(f"{len(messages)} camera messages in {len(source.frames)} ticks")  # type: ignore[arg-type]
    except ValueError as exc:
        raise UserError(str(exc)) from None
    thresholds = site.thresholds if site is not None else Thresholds()
    tolerance = args.tolerance if args.tolerance is not None else thresholds.fusion_distance_m
    rows = check_consistency(source.cameras, source.camera_ids, source.frames, gate_m=args.gate, pairing=args.pairing)
    if not rows:
        raise UserError("no person was seen by two cameras at once: do the cameras overlap? try more --frames or a wider --gate")
    print(format_consistency(rows, args.min_samples))
    _print_verdict([r for r in rows if r.samples >= args.min_samples], tolerance, args.site)
    return 0


def _print_verdict(rows: list[PairConsistency], tolerance: float, site: str | None) -> None:
    bad = [r for r in rows if r.median_offset_m > tolerance]
    print()
    if not rows:
        print("no pair has enough samples to judge: listen longer (--live, --frames) or lower --min-samples")
        return
    if not bad:
        print(f"every pair agrees within {tolerance:g} m (people are fused across cameras).")
        print(f"next: start the system: bevflow serve ... --site {site or 'SITE'} (see docs/INSTALL.md)")
        return
    counts: dict[str, int] = {}
    for r in bad:
        for cam in (r.camera_a, r.camera_b):
            counts[cam] = counts.get(cam, 0) + 1
    likely = sorted(counts, key=lambda c: -counts[c])
    print(f"{len(bad)} pair(s) disagree by more than {tolerance:g} m: people there would be counted twice.")
    print(f"next: redo the extrinsics of the camera found in most of them ({likely[0]}), then run this check again:")
    print(f"  bevflow calibrate extrinsics --camera {likely[0]} --site {site or 'SITE'} --points POINTS.csv")


def _load_dataset(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from bevflow.datasets.wildtrack import WildtrackError, load_wildtrack

    if args.root is None:
        raise UserError(f"--dataset {args.dataset} needs --root DIR (the dataset folder)")
    try:
        return load_wildtrack(args.root)
    except WildtrackError as exc:
        raise UserError(str(exc)) from None


def _read_messages(path: Path) -> list[CameraCylinders]:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise UserError(f"--cylinders {path}: cannot read ({exc.strerror or exc})") from None
    messages = []
    for number, line in enumerate(lines, start=1):
        if line.strip():
            try:
                messages.append(CameraCylinders.model_validate_json(line))
            except ValidationError:
                raise UserError(f"{path}:{number}: not a CameraCylinders message") from None
    return messages


def _listen(site: Site, args: argparse.Namespace) -> list[CameraCylinders]:
    """The projector's messages of the running site for ``args.live`` seconds (kept in
    ``args.save`` as JSON lines when given)."""
    import threading
    import time

    from bevflow_services import bus

    if not args.live > 0:
        raise UserError(f"--live must be a number of seconds above 0, got {args.live:g}")
    received: list[CameraCylinders] = []
    lock = threading.Lock()

    def keep(message: CameraCylinders) -> None:  # on a Zenoh thread
        with lock:
            received.append(message)

    try:
        session = bus.open_session(bus.config_from_args(args))
    except bus.BusError as exc:
        raise UserError(str(exc)) from None
    try:
        subscription = bus.subscribe(session, bus.Keys(site.site).cylinders("*"), bus.JsonCodec(CameraCylinders), keep)
        print(f"listening to the cameras of site {site.site!r} for {args.live:g} s; people should walk through the overlaps")
        time.sleep(args.live)
        subscription.close()
    finally:
        session.close()
    with lock:
        messages = list(received)
    if args.save is not None:
        args.save.write_text("".join(m.model_dump_json() + "\n" for m in messages), encoding="utf-8")
        print(f"saved the recording to {args.save} (rerun the check with --cylinders {args.save})")
    if not messages:
        raise UserError(f"nothing heard from site {site.site!r} in {args.live:g} s: are the projectors running, and the bus flags right?")
    return messages


# --- shared ---------------------------------------------------------------------------------------
def _load_site_file(path: Path) -> Site:
    if not path.is_file():
        raise UserError(f"--site {path}: no such file (calibration writes into an existing site file; start from "
                        "`bevflow plan ... --out site.yaml` or the example site)")
    try:
        return load_site(path)
    except SiteError as exc:
        raise UserError(str(exc)) from None


def _load_any_site(value: str) -> Site:
    try:
        return load_site_or_builtin(value)
    except SiteError as exc:
        raise UserError(str(exc)) from None


def _camera_config(site: Site, camera_id: str, path: Path) -> CameraConfig:
    for config in site.cameras:
        if config.id == camera_id:
            return config
    raise UserError(f"{path}: no camera {camera_id!r}; its cameras are {', '.join(site.camera_ids)}")


def _save(args: argparse.Namespace, changes: dict, what: str) -> None:
    if args.dry_run:
        print(f"--dry-run: {args.site} is unchanged")
        return
    try:
        result = update_camera_file(args.site, args.camera, changes)
    except SiteError as exc:
        raise UserError(str(exc)) from None
    kept = "" if result.comments_kept else " (its layout could not be kept, so the file was written again without comments)"
    print(f"wrote {what} of {args.camera} into {args.site}{kept}; the previous version is {args.site}.bak")
