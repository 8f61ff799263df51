"""What to assume about a fisheye frame that comes without calibration: where its image circle is,
the focal length that circle implies, and a typical ceiling height.

The detector's input scale needs a camera height and a focal length (``bevflow.detect.scaling``).
A frame from an unknown camera has neither, but a fisheye frame shows its lens: the image circle,
bright inside, dark outside (or cut by the sensor's edges, as on 1920 × 1080 frames). For an
equidistant lens the circle's radius is f · θmax, so a lens of 180–200° (most ceiling fisheyes)
gives f = radius / 1.66 at 190°, within 5 % of either end of that range. A ceiling of about 3 m is
the common case (offices, shops, meeting rooms); higher ones are usually calibrated sites.

The circle is found by thresholding the dark border on a reduced copy of the frame, keeping the
largest bright region (burnt-in text on the border is not part of it), and fitting a circle to
its outline where the outline does not run along the frame's edge. Points pulled inward by dark
parts of the scene at the rim are dropped and the fit repeated.

>>> frame = np.zeros((400, 600, 3), np.uint8)
>>> _ = cv2.circle(frame, (300, 200), 150, (90, 120, 140), -1)
>>> c = find_image_circle(frame)
>>> c.found, round(c.cx), round(c.cy), round(c.radius)
(True, 300, 200, 150)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

DEFAULT_CEILING_M = 3.0
DEFAULT_FIELD_OF_VIEW_DEG = 190.0  # the middle of the 180–200° of common ceiling fisheyes
DARK_LEVEL = 24  # a border pixel is darker than this in every channel (JPEG noise reaches ~10)
WORK_SIDE_PX = 512  # the frame is reduced to this longer side to find the circle
MIN_RADIUS_SHARE = 0.25  # a circle smaller than this share of the frame's shorter side is noise
EDGE_PX = 2  # outline points this close to the frame's edge are the sensor's cut, not the lens
TRIM_PX = 2.0  # outline points this far inside the fitted circle are scene, not border


@dataclass(frozen=True)
class ImageCircle:
    """The lens's image circle in frame pixels; ``found`` is False when the frame shows no dark
    border (the circle is then assumed to reach the frame's corners)."""

    cx: float
    cy: float
    radius: float
    found: bool


@dataclass(frozen=True)
class AssumedCalibration:
    """What a frame without calibration is taken to be."""

    camera_height_m: float
    focal_px: float
    circle: ImageCircle
    field_of_view_deg: float

    def describe(self) -> str:
        c = self.circle
        where = (f"image circle centre ({c.cx:.0f}, {c.cy:.0f}), radius {c.radius:.0f} px" if c.found
                 else f"no image circle found, assumed to reach the corners (radius {c.radius:.0f} px)")
        return (f"{where}; focal length {self.focal_px:.0f} px for a {self.field_of_view_deg:g}° equidistant lens; "
                f"camera {self.camera_height_m:g} m above the floor")  # fmt: skip


def find_image_circle(image_bgr: NDArray[np.uint8], dark_level: int = DARK_LEVEL) -> ImageCircle:
    """The image circle of a fisheye frame (H, W, 3), or the frame's circumscribed circle with
    ``found`` False when no dark border shows one."""
    h, w = image_bgr.shape[:2]
    fallback = ImageCircle((w - 1) / 2, (h - 1) / 2, math.hypot(w, h) / 2, False)
    k = min(1.0, WORK_SIDE_PX / max(h, w))
    small = cv2.resize(image_bgr, (max(round(w * k), 1), max(round(h * k), 1)), interpolation=cv2.INTER_AREA) if k < 1 else image_bgr
    points = _outline(small.max(axis=2) >= dark_level)
    if points is None:
        return fallback
    fit = _robust_circle(points)
    if fit is None or fit[2] < MIN_RADIUS_SHARE * min(small.shape[:2]):
        return fallback
    cx, cy, r = fit
    # Pixel centres: x = (x' + 0.5) / k − 0.5.
    return ImageCircle((cx + 0.5) / k - 0.5, (cy + 0.5) / k - 0.5, r / k, True)


def _outline(bright: NDArray[np.bool_]) -> NDArray[np.float64] | None:
    """The outline of the largest bright region, without the stretches along the frame's edge;
    None when there is no region or it fills the frame."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(bright.astype(np.uint8), connectivity=8)
    if count < 2:
        return None
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    region = (labels == largest).astype(np.uint8)
    contours, _ = cv2.findContours(region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pts = max(contours, key=len).reshape(-1, 2).astype(np.float64)
    h, w = bright.shape
    inner = (pts[:, 0] > EDGE_PX) & (pts[:, 0] < w - 1 - EDGE_PX) & (pts[:, 1] > EDGE_PX) & (pts[:, 1] < h - 1 - EDGE_PX)
    pts = pts[inner]
    return pts if len(pts) >= 12 else None


def _robust_circle(points: NDArray[np.float64], rounds: int = 4) -> tuple[float, float, float] | None:
    """Least-squares circle (Kåsa) through ``points``, refitted without the points well inside it:
    dark furniture or clothing at the rim notches the bright region inward, never outward."""
    keep = np.ones(len(points), dtype=bool)
    fit = None
    for _ in range(rounds):
        if keep.sum() < 12:
            break
        fit = _kasa(points[keep])
        residual = np.hypot(points[:, 0] - fit[0], points[:, 1] - fit[1]) - fit[2]
        keep = residual > -TRIM_PX
    return fit


def _kasa(p: NDArray[np.float64]) -> tuple[float, float, float]:
    # x² + y² = 2 a x + 2 b y + c, linear in (a, b, c); r² = c + a² + b².
    a = np.column_stack([2 * p[:, 0], 2 * p[:, 1], np.ones(len(p))])
    (cx, cy, c), *_ = np.linalg.lstsq(a, (p**2).sum(axis=1), rcond=None)
    return float(cx), float(cy), float(math.sqrt(max(c + cx * cx + cy * cy, 0.0)))


def assume_calibration(
    image_bgr: NDArray[np.uint8], camera_height_m: float = DEFAULT_CEILING_M, field_of_view_deg: float = DEFAULT_FIELD_OF_VIEW_DEG
) -> AssumedCalibration:
    """A camera height and focal length for a frame that has no calibration: f from the image
    circle of an equidistant lens of ``field_of_view_deg``, the camera ``camera_height_m`` high."""
    if not 90.0 <= field_of_view_deg <= 270.0:
        raise ValueError(f"field of view must be 90-270 degrees, got {field_of_view_deg:g}")
    circle = find_image_circle(image_bgr)
    focal = circle.radius / math.radians(field_of_view_deg / 2)
    return AssumedCalibration(camera_height_m, focal, circle, field_of_view_deg)
