"""Coverage planning: how many ceiling fisheyes a hall needs, where they hang, what each covers.

**Usable range.** The detector sees each frame rescaled so that a person straight below the camera
is about 20 px wide (paper, section 3.4). Farther out a person looks narrower: with an
equidistant lens (r = f·θ) a shoulder width w at floor distance d, seen from D = H − 1.4 m above
shoulder height, spans f·w·atan(d/D)/d pixels across, against f·w/D below the camera. The rule
used here: a person is usable while they stay at least 56 % as wide as at the centre (11 of the
20 px), which holds while

    atan(x)/x >= 0.56, x = d/D   ->   d <= 1.955 · (H − 1.4 m)

and the radius is also capped at 10 m, the farthest the paper claims, and by the lens: the heads
(1.7 m) at the rim must lie inside the lens's field of view. The rule gives, for the paper's
mounting heights (Table 1 radii in brackets): 3.7 m at 3.3 m (3.5, whose room was 7 m wide),
8.0 m at 5.5 m (8) and 10 m at 8.1 m (10; the rule alone gives 13.1 m). It is rounded down to 0.1 m.

**Layout.** Cameras sit at the centres of a ``cols × rows`` grid of equal cells over the floor.
The plan with the fewest cameras is chosen such that

- the whole floor is covered: every cell's corners lie within the radius of the cell's camera;
- neighbours overlap by at least ``overlap_m`` along the line between them, so that someone
  walking from one camera to the next is seen by both for a while and fused (the paper requires a
  small overlap; fusion merges within 0.45 m, and a person is about 0.5 m wide: 1 m by default).

Ties go to the plan with the larger margin at the worst-covered point.

>>> plan = plan_layout(width_m=40.0, depth_m=25.0, ceiling_m=5.5, lens_fov_deg=185.0)
>>> (plan.cols, plan.rows, plan.radius_m)
(3, 3, 8.0)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from bevflow.camera import FisheyeCamera
from bevflow.remap import BevGrid
from bevflow.site import CameraConfig, Intrinsics, Pose, Site, Thresholds

FloatArray = NDArray[np.float64]

CENTRE_WIDTH_PX = 20.0  # a person straight below the camera, after the detector's rescale (paper)
MIN_WIDTH_PX = 11.2  # the narrowest a person may look at the rim of the monitored circle
SHOULDER_HEIGHT_M = 1.4
HEAD_HEIGHT_M = 1.7
MAX_RADIUS_M = 10.0
CEILING_RANGE_M = (3.0, 10.0)  # the paper's two detector models: 3–6 m and 6–10 m


class PlanError(ValueError):
    """A hall or lens no plan can serve; ``str()`` says why."""


def usable_radius(ceiling_m: float, lens_fov_deg: float = 185.0, min_width_px: float = MIN_WIDTH_PX) -> float:
    """The monitored radius (m, on the floor) of a fisheye at ``ceiling_m``; see the module notes."""
    lo, hi = CEILING_RANGE_M
    if not lo <= ceiling_m <= hi:
        raise PlanError(f"the detector is made for cameras {lo:g} to {hi:g} m high, not {ceiling_m:g} m")
    if not 60.0 <= lens_fov_deg <= 240.0:
        raise PlanError(f"a ceiling fisheye's field of view is 60 to 240 degrees, not {lens_fov_deg:g}")
    ratio = min_width_px / CENTRE_WIDTH_PX
    x = brentq(lambda v: math.atan(v) / v - ratio, 1e-6, 1e6)  # atan(x)/x falls from 1 to 0
    detector = x * (ceiling_m - SHOULDER_HEIGHT_M)
    half = math.radians(lens_fov_deg / 2.0)
    lens = math.tan(half) * (ceiling_m - HEAD_HEIGHT_M) if half < math.radians(89.0) else math.inf
    return math.floor(min(detector, lens, MAX_RADIUS_M) * 10.0 + 1e-9) / 10.0


@dataclass(frozen=True)
class CameraPlan:
    """Cameras at the centres of a ``cols × rows`` grid of cells over a ``width_m × depth_m`` floor."""

    width_m: float
    depth_m: float
    ceiling_m: float
    lens_fov_deg: float
    radius_m: float
    overlap_m: float
    cols: int
    rows: int

    @property
    def cell(self) -> tuple[float, float]:
        return self.width_m / self.cols, self.depth_m / self.rows

    @cached_property
    def positions(self) -> FloatArray:
        """(N, 2) camera floor positions, row by row from the origin corner."""
        sx, sy = self.cell
        xs = (np.arange(self.cols) + 0.5) * sx
        ys = (np.arange(self.rows) + 0.5) * sy
        return np.array([(x, y) for y in ys for x in xs])

    @property
    def margin_m(self) -> float:
        """How far inside its camera's circle the worst-covered floor point lies."""
        sx, sy = self.cell
        return self.radius_m - math.hypot(sx / 2.0, sy / 2.0)

    @property
    def neighbour_overlap_m(self) -> tuple[float | None, float | None]:
        """Overlap of neighbouring circles along a row and along a column (None: no neighbour)."""
        sx, sy = self.cell
        return (2 * self.radius_m - sx if self.cols > 1 else None, 2 * self.radius_m - sy if self.rows > 1 else None)

    def camera_ids(self) -> list[str]:
        return [f"cam-{r + 1}-{c + 1}" for r in range(self.rows) for c in range(self.cols)]

    def coverage(self, grid: BevGrid) -> NDArray[np.int64]:
        """(h, w) how many monitored circles cover each pixel of ``grid``."""
        w, h = grid.size
        u, v = np.meshgrid(np.arange(w), np.arange(h))
        floor = grid.pixels_to_world(np.stack([u.ravel(), v.ravel()], axis=1))[:, :2]
        d = np.linalg.norm(floor[:, None, :] - self.positions[None, :, :], axis=2)
        counts: NDArray[np.int64] = (d <= self.radius_m).sum(axis=1).reshape(h, w)
        return counts

    def to_site(self, name: str = "site", image_size: tuple[int, int] = (1280, 1280)) -> Site:
        """A site file for the plan: nominal equidistant lenses (calibrate them once mounted),
        cameras looking straight down, the floor extent, no zones yet."""
        cameras = []
        for camera_id, (x, y) in zip(self.camera_ids(), self.positions, strict=True):
            position = (round(float(x), 3), round(float(y), 3), float(self.ceiling_m))
            lens = FisheyeCamera.looking_down(position, image_size, fov_deg=self.lens_fov_deg)
            K = lens.K
            cameras.append(
                CameraConfig(
                    id=camera_id,
                    model="fisheye",
                    image_size=image_size,
                    intrinsics=Intrinsics(fx=round(K[0, 0], 3), fy=round(K[1, 1], 3), cx=K[0, 2], cy=K[1, 2]),
                    distortion=[0.0, 0.0, 0.0, 0.0],
                    pose=Pose(position=position),
                    monitored_radius_m=self.radius_m,
                )
            )
        return Site(site=name, cameras=cameras, floor=(0.0, 0.0, self.width_m, self.depth_m), thresholds=Thresholds())


def plan_layout(
    width_m: float, depth_m: float, ceiling_m: float, lens_fov_deg: float = 185.0, overlap_m: float = 1.0, max_cameras: int = 400
) -> CameraPlan:
    """The plan with the fewest cameras that covers the floor with ``overlap_m`` between neighbours."""
    if not (width_m > 0 and depth_m > 0 and math.isfinite(width_m) and math.isfinite(depth_m)):
        raise PlanError(f"the hall must have a positive width and depth, got {width_m:g} x {depth_m:g} m")
    if not 0.0 <= overlap_m:
        raise PlanError(f"the overlap must be 0 m or more, got {overlap_m:g}")
    radius = usable_radius(ceiling_m, lens_fov_deg)
    if overlap_m >= 2 * radius:
        raise PlanError(f"an overlap of {overlap_m:g} m is more than a camera's whole circle ({2 * radius:g} m across)")
    best: CameraPlan | None = None
    for cols in range(1, max_cameras + 1):
        for rows in range(1, max_cameras // cols + 1):
            plan = CameraPlan(width_m, depth_m, ceiling_m, lens_fov_deg, radius, overlap_m, cols, rows)
            if not _feasible(plan):
                continue
            key = (cols * rows, -plan.margin_m)
            if best is None or key < (best.cols * best.rows, -best.margin_m):
                best = plan
            break  # more rows with these columns only adds cameras
    if best is None:
        raise PlanError(f"no grid of at most {max_cameras} cameras covers {width_m:g} x {depth_m:g} m at {ceiling_m:g} m")
    return best


def _feasible(plan: CameraPlan) -> bool:
    if plan.margin_m < -1e-9:
        return False
    return all(o is None or o >= plan.overlap_m - 1e-9 for o in plan.neighbour_overlap_m)


# --- the coverage map ---------------------------------------------------------------------------
_COLOURS = {0: (60, 60, 220), 1: (140, 210, 140), 2: (215, 170, 90)}  # BGR: gap red, one green, overlap blue
_OUTSIDE = (45, 45, 45)


def coverage_map(plan: CameraPlan, pixels_per_metre: float = 20.0, margin_m: float = 2.0) -> NDArray[np.uint8]:
    """A BGR picture of the plan seen from above: the floor coloured by how many cameras cover
    it (red: none, green: one, blue: two or more), each camera's circle, position and id, and a
    scale bar. X points right, Y up, as on the dashboard's floor map."""
    extent = (-margin_m, -margin_m, plan.width_m + margin_m, plan.depth_m + margin_m + 2.0)  # room for the legend
    grid = BevGrid(extent, 1.0 / pixels_per_metre)
    count = np.minimum(plan.coverage(grid), 2)
    w, h = grid.size
    image = np.empty((h, w, 3), np.uint8)
    for level, colour in _COLOURS.items():
        image[count == level] = colour
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    floor = grid.pixels_to_world(np.stack([u.ravel(), v.ravel()], axis=1))[:, :2].reshape(h, w, 2)
    inside = (floor[..., 0] >= 0) & (floor[..., 0] <= plan.width_m) & (floor[..., 1] >= 0) & (floor[..., 1] <= plan.depth_m)
    image[~inside] = _OUTSIDE

    def px(xy: tuple[float, float]) -> tuple[int, int]:
        p = grid.world_to_pixels(np.array([xy]))[0]
        return int(round(p[0])), int(round(p[1]))

    cv2.rectangle(image, px((0.0, plan.depth_m)), px((plan.width_m, 0.0)), (255, 255, 255), 2)
    radius_px = int(round(plan.radius_m * pixels_per_metre))
    for camera_id, (x, y) in zip(plan.camera_ids(), plan.positions, strict=True):
        centre = px((x, y))
        cv2.circle(image, centre, radius_px, (40, 40, 40), 1, cv2.LINE_AA)
        cv2.drawMarker(image, centre, (0, 0, 0), cv2.MARKER_CROSS, 14, 2)
        cv2.putText(image, camera_id, (centre[0] + 6, centre[1] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    _legend(image, plan, grid, px)
    return image


def _legend(
    image: NDArray[np.uint8], plan: CameraPlan, grid: BevGrid, px: Callable[[tuple[float, float]], tuple[int, int]]
) -> None:
    top = plan.depth_m + 1.6
    bar = 5.0 if plan.width_m >= 8 else 1.0
    a, b = px((0.0, top)), px((bar, top))
    cv2.line(image, a, b, (255, 255, 255), 3)
    cv2.putText(image, f"{bar:g} m", (b[0] + 6, b[1] + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    text = (
        f"{plan.cols * plan.rows} cameras at {plan.ceiling_m:g} m, radius {plan.radius_m:g} m | "
        "red: not covered  green: one camera  blue: overlap"
    )
    x = b[0] + 60
    cv2.putText(image, text, (x, b[1] + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
