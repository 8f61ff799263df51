"""Where a camera hangs: its pose from image ↔ floor correspondences.

The technician marks at least four points whose floor position is known (tape marks, tile
corners, the foot of a pillar) and reads their pixels off a still frame. The lens (K, D) must be
calibrated first.

Method, for any lens: pixels become unit rays through the calibrated model (for a fisheye, this is
the undistortion; rays up to 80° off axis are usable on a normalised image plane), a PnP solver on
those normalised points with an identity K gives the starting pose (SQPnP, and IPPE too when the
points are coplanar), and Levenberg–Marquardt then minimises the reprojection error in pixels
through the true lens model. Each point's error is reported twice: in pixels (where the fitted
pose puts the world point in the image) and in metres (where the point's pixel lands on its own
plane Z = z, against its measured position).

Points file, CSV (a header row names the columns; ``z`` defaults to 0, ``name`` to the row
number; lines starting with ``#`` are comments)::

    name,u,v,x,y,z
    door-left,512.3,880.1,0.0,4.0,0.0

or YAML (``world`` with two numbers lies on the floor)::

    points:
      - {name: door-left, pixel: [512.3, 880.1], world: [0.0, 4.0]}
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.optimize import least_squares

from bevflow.camera import Camera, rotation_from_vector, rotation_vector, tilt_deg

Array = NDArray[np.float64]

MIN_POINTS = 4
CHECKABLE_POINTS = 6
_MAX_INIT_ANGLE_DEG = 80.0


class ExtrinsicsError(ValueError):
    """Points that cannot give a pose, or a pose that is refused; ``str()`` is for the technician."""


@dataclass(frozen=True)
class Correspondences:
    """Row-aligned: ``pixels`` (N, 2), ``world`` (N, 3) metres, ``names`` (N,)."""

    pixels: Array
    world: Array
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class PoseFit:
    """The fitted world-to-camera ``R``, ``t``; per point ``reprojection_px`` and ``ground_error_m``."""

    R: Array
    t: Array
    reprojection_px: Array
    ground_error_m: Array
    points: Correspondences

    @property
    def rvec(self) -> Array:
        return rotation_vector(self.R)

    @property
    def center(self) -> Array:
        return -self.R.T @ self.t

    @property
    def tilt_deg(self) -> float:
        """Angle between the optical axis and straight down (``bevflow.camera.tilt_deg``)."""
        return tilt_deg(self.R)

    @property
    def rms_px(self) -> float:
        return float(np.sqrt(np.mean(self.reprojection_px**2)))

    @property
    def rms_ground_m(self) -> float:
        return float(np.sqrt(np.mean(self.ground_error_m**2)))


# --- reading points -------------------------------------------------------------------------------
def load_correspondences(path: str | Path) -> Correspondences:
    """Read a points file (``.csv``, or ``.yaml``/``.yml``/``.json``); see the module notes."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ExtrinsicsError(f"{path}: cannot read the points file ({exc.strerror or exc})") from None
    if path.suffix.lower() == ".csv":
        return parse_points_csv(text, source=str(path))
    return parse_points_yaml(text, source=str(path))


def parse_points_csv(text: str, source: str = "<points>") -> Correspondences:
    lines = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ExtrinsicsError(f"{source}: no points (expected a header 'name,u,v,x,y,z' and one row per point)")
    rows = list(csv.DictReader(io.StringIO("\n".join(lines)), skipinitialspace=True))
    header = [h.strip().lower() for h in (csv.reader([lines[0]], skipinitialspace=True).__next__())]
    missing = [c for c in ("u", "v", "x", "y") if c not in header]
    if missing:
        raise ExtrinsicsError(f"{source}: the header needs columns u, v, x, y (z and name optional); missing {', '.join(missing)}")
    points = []
    for k, row in enumerate(rows, start=1):
        values = {(key or "").strip().lower(): (value or "").strip() for key, value in row.items()}
        name = values.get("name") or str(k)
        try:
            pixel = [float(values["u"]), float(values["v"])]
            world = [float(values["x"]), float(values["y"]), float(values.get("z") or 0.0)]
        except ValueError:
            raise ExtrinsicsError(f"{source}: point {name!r} (row {k}): u, v, x, y, z must be numbers") from None
        points.append((name, pixel, world))
    return _correspondences(points, source)


def parse_points_yaml(text: str, source: str = "<points>") -> Correspondences:
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ExtrinsicsError(f"{source}: not valid YAML ({getattr(exc, 'problem', None) or exc})") from None
    items = raw.get("points") if isinstance(raw, dict) else raw
    if not isinstance(items, list):
        raise ExtrinsicsError(f"{source}: expected 'points:' with a list of {{name, pixel: [u, v], world: [x, y, z]}}")
    points = []
    for k, item in enumerate(items, start=1):
        name = str(item.get("name", k)) if isinstance(item, dict) else str(k)
        try:
            pixel = [float(v) for v in item["pixel"]]
            world = [float(v) for v in item["world"]]
        except (TypeError, KeyError, ValueError):
            raise ExtrinsicsError(f"{source}: point {name!r}: needs pixel: [u, v] and world: [x, y] or [x, y, z], as numbers") from None
        if len(pixel) != 2 or len(world) not in (2, 3):
            raise ExtrinsicsError(f"{source}: point {name!r}: pixel needs 2 numbers and world 2 or 3")
        points.append((name, pixel, world + [0.0] * (3 - len(world))))
    return _correspondences(points, source)


def make_correspondences(
    points: Sequence[tuple[str, Sequence[float], Sequence[float]]], source: str = "<points>"
) -> Correspondences:
    """Correspondences from ``(name, (u, v), (x, y) or (x, y, z))`` rows, as a form or an API
    sends them (a floor point may leave out z); ``ExtrinsicsError`` names the first bad point."""
    rows = []
    for name, pixel, world in points:
        if len(pixel) != 2 or len(world) not in (2, 3):
            raise ExtrinsicsError(f"{source}: point {name!r}: pixel needs 2 numbers and world 2 or 3")
        rows.append((str(name), [float(v) for v in pixel], [float(v) for v in world] + [0.0] * (3 - len(world))))
    return _correspondences(rows, source)


def _correspondences(points: list[tuple[str, list[float], list[float]]], source: str) -> Correspondences:
    names = tuple(p[0] for p in points)
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ExtrinsicsError(f"{source}: point names must be unique; repeated: {', '.join(repeated)}")
    pixels = np.array([p[1] for p in points], dtype=np.float64).reshape(-1, 2)
    world = np.array([p[2] for p in points], dtype=np.float64).reshape(-1, 3)
    if not (np.isfinite(pixels).all() and np.isfinite(world).all()):
        raise ExtrinsicsError(f"{source}: every coordinate must be a finite number")
    return Correspondences(pixels, world, names)


# --- fitting --------------------------------------------------------------------------------------
def estimate_pose(camera: Camera, points: Correspondences) -> PoseFit:
    """The pose of ``camera`` (its K and distortion; its current pose is ignored) that best maps
    ``points.world`` onto ``points.pixels``. Raises ``ExtrinsicsError`` for unusable points."""
    _check_geometry(camera, points)
    rays = camera.rays(points.pixels)
    best: tuple[float, Array, Array] | None = None
    for rvec, tvec in _initial_poses(rays, points.world):
        rvec, tvec = _refine(camera, points, rvec, tvec)
        cost = float(np.nansum(_residuals(np.concatenate([rvec, tvec]), camera, points) ** 2))
        if best is None or cost < best[0]:
            best = (cost, rvec, tvec)
    if best is None:
        raise ExtrinsicsError("no starting pose could be found from these points; check that pixels and world points match")
    R = rotation_from_vector(best[1])
    return _fit(camera, points, R, best[2])


def check_fit(fit: PoseFit, max_rms_px: float, max_ground_error_m: float) -> None:
    """Refuse a fit whose RMS reprojection error or worst ground error is beyond the limits,
    naming the worst point."""
    worst = int(np.argmax(fit.ground_error_m))
    name = fit.points.names[worst]
    if fit.rms_px > max_rms_px or fit.ground_error_m[worst] > max_ground_error_m:
        raise ExtrinsicsError(
            f"pose refused: RMS reprojection {fit.rms_px:.2f} px (limit {max_rms_px:g}), worst ground error "
            f"{fit.ground_error_m[worst]:.3f} m at point {name!r} (limit {max_ground_error_m:g} m); check that "
            f"point's pixel and floor coordinates, or remove it"
        )


def _check_geometry(camera: Camera, points: Correspondences) -> None:
    if len(points) < MIN_POINTS:
        raise ExtrinsicsError(f"{len(points)} points given; at least {MIN_POINTS} are needed ({CHECKABLE_POINTS} or more to check them)")
    outside = [n for n, ok in zip(points.names, camera.in_image(points.pixels), strict=True) if not ok]
    if outside:
        w, h = camera.image_size
        raise ExtrinsicsError(f"point(s) {', '.join(outside)}: pixel outside the {w}x{h} image")
    unseen = [n for n, r in zip(points.names, camera.rays(points.pixels), strict=True) if not np.isfinite(r).all()]
    if unseen:
        raise ExtrinsicsError(f"point(s) {', '.join(unseen)}: pixel beyond the calibrated lens (outside the image circle?)")
    centred = points.world - points.world.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)
    if spread[1] < 0.05 * max(spread[0], 1e-9):
        raise ExtrinsicsError("the world points lie (almost) on one line; spread them over the camera's view")


def _initial_poses(rays: Array, world: Array) -> list[tuple[Array, Array]]:
    usable = rays[:, 2] > math.cos(math.radians(_MAX_INIT_ANGLE_DEG))
    if usable.sum() < MIN_POINTS:
        usable = rays[:, 2] > 1e-3
    if usable.sum() < MIN_POINTS:
        return []
    image = np.ascontiguousarray(rays[usable, :2] / rays[usable, 2:3]).reshape(-1, 1, 2)
    objects = np.ascontiguousarray(world[usable]).reshape(-1, 1, 3)
    methods = [cv2.SOLVEPNP_SQPNP]
    if np.ptp(world[usable, 2]) < 1e-9:
        methods.append(cv2.SOLVEPNP_IPPE)
    poses = []
    for method in methods:
        try:
            ok, rvec, tvec = cv2.solvePnP(objects, image, np.eye(3), None, flags=method)
        except cv2.error:
            continue
        if ok and np.isfinite(rvec).all() and np.isfinite(tvec).all():
            poses.append((np.asarray(rvec, dtype=np.float64).ravel(), np.asarray(tvec, dtype=np.float64).ravel()))
    return poses


def _residuals(params: Array, camera: Camera, points: Correspondences) -> Array:
    R = rotation_from_vector(params[:3])
    projected = camera.with_pose(R, params[3:]).project(points.world)
    # A point the trial pose cannot see gets a large, smooth penalty instead of NaN.
    return np.nan_to_num(projected - points.pixels, nan=1e4).ravel()


def _refine(camera: Camera, points: Correspondences, rvec: Array, tvec: Array) -> tuple[Array, Array]:
    start = np.concatenate([rvec, tvec])
    method: Literal["lm", "trf"] = "lm" if 2 * len(points) >= 6 else "trf"
    solution = least_squares(_residuals, start, args=(camera, points), method=method, x_scale="jac")
    return solution.x[:3], solution.x[3:]


def _fit(camera: Camera, points: Correspondences, R: Array, t: Array) -> PoseFit:
    posed = camera.with_pose(R, t)
    reprojection = np.linalg.norm(posed.project(points.world) - points.pixels, axis=1)
    landed = posed.pixels_to_plane(points.pixels, points.world[:, 2])
    ground = np.linalg.norm(landed[:, :2] - points.world[:, :2], axis=1)
    return PoseFit(
        R=R,
        t=np.asarray(t, dtype=np.float64),
        reprojection_px=np.nan_to_num(reprojection, nan=np.inf),
        ground_error_m=np.nan_to_num(ground, nan=np.inf),
        points=points,
    )


def pose_summary(fit: PoseFit) -> dict[str, Any]:
    """The fit as plain numbers, for printing and for the site file's extrinsics."""
    return {
        "rvec": [float(v) for v in fit.rvec],
        "tvec": [float(v) for v in fit.t],
        "center": [float(v) for v in fit.center],
        "tilt_deg": fit.tilt_deg,
        "rms_px": fit.rms_px,
        "rms_ground_m": fit.rms_ground_m,
    }
