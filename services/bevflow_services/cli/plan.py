"""``bevflow plan``: how many ceiling fisheyes a hall needs and where to hang them.

Prints the layout, writes a site file to start from (nominal lenses, cameras looking straight
down) and a coverage map picture. The rule for the monitored radius and the layout are in
``bevflow.planning``.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import cv2

from bevflow.planning import CameraPlan, PlanError, coverage_map, plan_layout
from bevflow.site import dump_site

from bevflow_services.runtime import UserError

EPILOG = """\
example:
  bevflow plan --width 40 --depth 25 --ceiling 5.5 --lens-fov 185 --out site.yaml --png coverage.png

The monitored radius follows from the mounting height: a person at the edge of a camera's circle
must still look at least 56 % as wide as one straight below it (11 of the detector's 20 px), which
gives radius = 1.955 x (ceiling - 1.4 m), at most 10 m, and heads must stay inside the lens's field
of view: 3.7 m at 3.3 m, 8.0 m at 5.5 m, 10 m from 6.5 m up.
Exit status: 0 on success, 2 for a usage or input error (message on stderr)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "plan",
        help="propose a camera layout for a hall and write a site file and a coverage map",
        description="Propose where to hang ceiling fisheye cameras so the whole floor is covered and neighbouring "
        "cameras overlap enough to follow people from one to the next.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--width", type=float, required=True, metavar="M", help="floor size along X, metres")
    parser.add_argument("--depth", type=float, required=True, metavar="M", help="floor size along Y, metres")
    parser.add_argument("--ceiling", type=float, required=True, metavar="M", help="height the cameras hang at (lens above floor), metres")
    parser.add_argument("--lens-fov", type=float, default=185.0, metavar="DEG", help="the lens's field of view in degrees (default 185)")
    parser.add_argument("--overlap", type=float, default=1.0, metavar="M", help="least overlap between neighbouring cameras, metres (default 1.0)")
    parser.add_argument("--image-size", default="1280x1280", metavar="WxH", help="the cameras' frame size in pixels (default 1280x1280)")
    parser.add_argument("--name", default="site", metavar="NAME", help="short site name for the site file (default 'site')")
    parser.add_argument("--out", type=Path, metavar="SITE", help="write the site file here (refuses to overwrite)")
    parser.add_argument("--png", type=Path, metavar="FILE", help="write the coverage map picture here")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    size = _image_size(args.image_size)
    try:
        plan = plan_layout(args.width, args.depth, args.ceiling, args.lens_fov, args.overlap)
    except PlanError as exc:
        raise UserError(str(exc)) from None
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", args.name):
        raise UserError(f"--name may hold only letters, digits, '_', '.' and '-', got {args.name!r}")
    site = plan.to_site(args.name, size)
    print(format_plan(plan))
    if args.out is not None:
        if args.out.exists():
            raise UserError(f"--out {args.out} exists; choose another name (calibration later edits this file in place)")
        try:
            args.out.write_text(_header(plan) + dump_site(site))
        except OSError as exc:
            raise UserError(f"cannot write {args.out}: {exc.strerror or exc}") from None
        print(f"wrote the site file {args.out} (nominal lenses: calibrate each camera once it hangs)")
    if args.png is not None:
        if args.png.suffix.lower() not in (".png", ".jpg", ".jpeg"):
            raise UserError(f"--png {args.png}: use a .png (or .jpg) file name")
        if not cv2.imwrite(str(args.png), coverage_map(plan)):
            raise UserError(f"cannot write {args.png}")
        print(f"wrote the coverage map {args.png}")
    if args.out is None:
        print("next: run again with --out site.yaml (and --png coverage.png to see the coverage)")
        return 0
    print("next: hang each camera at its position, lens straight down, then calibrate its lens:\n"
          f"  bevflow calibrate intrinsics --camera {plan.camera_ids()[0]} --site {args.out} --images SHOTS_DIR --board 9x6 --square 0.025")
    return 0


def format_plan(plan: CameraPlan) -> str:
    sx, sy = plan.cell
    along_row, along_col = plan.neighbour_overlap_m
    lines = [
        f"hall {plan.width_m:g} x {plan.depth_m:g} m, cameras at {plan.ceiling_m:g} m with a {plan.lens_fov_deg:g} degree lens",
        f"monitored radius per camera: {plan.radius_m:g} m",
        f"layout: {plan.cols} x {plan.rows} = {plan.cols * plan.rows} cameras, {sx:.2f} m apart along X, {sy:.2f} m along Y",
        f"overlap between neighbours: {_metres(along_row)} along X, {_metres(along_col)} along Y "
        f"(asked: at least {plan.overlap_m:g} m); worst-covered point {plan.margin_m:.2f} m inside a circle",
        "",
        f"{'camera':<10} {'x m':>8} {'y m':>8} {'height m':>9} {'radius m':>9}",
    ]
    for camera_id, (x, y) in zip(plan.camera_ids(), plan.positions, strict=True):
        lines.append(f"{camera_id:<10} {x:>8.2f} {y:>8.2f} {plan.ceiling_m:>9.2f} {plan.radius_m:>9.1f}")
    return "\n".join(lines)


def _metres(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f} m"


def _header(plan: CameraPlan) -> str:
    return (
        f"# Planned with: bevflow plan --width {plan.width_m:g} --depth {plan.depth_m:g} --ceiling {plan.ceiling_m:g} "
        f"--lens-fov {plan.lens_fov_deg:g} --overlap {plan.overlap_m:g}\n"
        "# Positions are where to hang each camera (x, y on the floor from the origin corner, height).\n"
        "# Intrinsics are nominal: run `bevflow calibrate intrinsics` and `extrinsics` for each camera.\n"
        "# Add zones (areas with capacities) at the end; see the example site for the fields.\n"
    )


def _image_size(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match or int(match.group(1)) < 64 or int(match.group(2)) < 64:
        raise UserError(f"--image-size must look like 1280x1280 (width x height, at least 64 each), got {text!r}")
    return int(match.group(1)), int(match.group(2))
