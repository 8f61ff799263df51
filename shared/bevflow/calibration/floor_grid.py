"""A picture of the floor as a camera's current calibration sees it: the metre grid, labelled,
drawn through the camera model.

The calibration page shows it when no frame of the camera has arrived (a site being set up, or a
simulated one). It is also a check on a calibration: laid over a real frame, the grid lines must
follow the floor tiles.

>>> from bevflow.camera import FisheyeCamera
>>> camera = FisheyeCamera.looking_down((5.0, 5.0, 4.0), (320, 320))
>>> render_floor_grid(camera, (0.0, 0.0, 10.0, 10.0)).shape
(320, 320, 3)
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera

Image = NDArray[np.uint8]
Extent = tuple[float, float, float, float]

BACKGROUND = (40, 32, 28)  # BGR
GRID = (110, 110, 110)
AXIS = (90, 200, 250)
LABEL = (220, 220, 220)
ZONE = (60, 180, 240)
NADIR = (80, 80, 255)
SAMPLE_M = 0.05  # step along a grid line: fine enough for the fisheye's curvature near the rim


def floor_extent(camera: Camera, floor: Extent | None, reach_m: float | None = None) -> Extent:
    """The part of the floor worth drawing for ``camera``: the site's ``floor`` clipped to
    ``reach_m`` (default: three mounting heights) around the point below the camera."""
    x, y, height = (float(v) for v in camera.center)
    reach = reach_m if reach_m is not None else 3.0 * max(height, 1.0)
    box = (x - reach, y - reach, x + reach, y + reach)
    if floor is None:
        return box
    clipped = (max(box[0], floor[0]), max(box[1], floor[1]), min(box[2], floor[2]), min(box[3], floor[3]))
    return clipped if clipped[2] > clipped[0] and clipped[3] > clipped[1] else box


def render_floor_grid(
    camera: Camera,
    extent: Extent,
    spacing_m: float = 1.0,
    label_every: int = 2,
    zones: Sequence[Sequence[tuple[float, float]]] = (),
) -> Image:
    """A BGR image of ``camera``'s size: grid lines every ``spacing_m`` over ``extent``
    (xmin, ymin, xmax, ymax), the X and Y axes in colour, ``x,y`` labels at every
    ``label_every``-th crossing, the ``zones`` outlines, and a cross below the camera."""
    if spacing_m <= 0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m}")
    w, h = camera.image_size
    image = np.full((h, w, 3), BACKGROUND, dtype=np.uint8)
    thickness = max(1, round(min(w, h) / 640))
    xmin, ymin, xmax, ymax = extent
    xs = spacing_m * np.arange(np.ceil(xmin / spacing_m), np.floor(xmax / spacing_m) + 1)
    ys = spacing_m * np.arange(np.ceil(ymin / spacing_m), np.floor(ymax / spacing_m) + 1)
    along_y = np.linspace(ymin, ymax, max(2, int((ymax - ymin) / SAMPLE_M) + 1))
    along_x = np.linspace(xmin, xmax, max(2, int((xmax - xmin) / SAMPLE_M) + 1))
    for x in xs:
        colour = AXIS if abs(x) < 1e-9 else GRID
        _polyline(image, camera, np.column_stack([np.full_like(along_y, x), along_y]), colour, thickness)
    for y in ys:
        colour = AXIS if abs(y) < 1e-9 else GRID
        _polyline(image, camera, np.column_stack([along_x, np.full_like(along_x, y)]), colour, thickness)
    for polygon in zones:
        _polyline(image, camera, _densify(np.asarray(polygon, dtype=np.float64)), ZONE, thickness + 1)
    _labels(image, camera, xs, ys, spacing_m, label_every, thickness)
    nadir = camera.project(np.array([[camera.center[0], camera.center[1], 0.0]]))[0]
    if np.isfinite(nadir).all():
        size = 6 * thickness
        cv2.drawMarker(image, tuple(int(round(v)) for v in nadir), NADIR, cv2.MARKER_CROSS, size, thickness)
    return image


def _polyline(image: Image, camera: Camera, floor_xy: NDArray[np.float64], colour: tuple[int, int, int], thickness: int) -> None:
    """Draw the floor path through the camera, broken where the camera does not see it."""
    pixels = camera.project(np.column_stack([floor_xy, np.zeros(len(floor_xy))]))
    seen: NDArray[np.bool_] = np.all(np.isfinite(pixels), axis=1)
    runs = np.split(np.arange(len(pixels)), np.flatnonzero(np.diff(seen.astype(np.int8))) + 1)
    for run in runs:
        if len(run) >= 2 and seen[run[0]]:
            points = np.round(pixels[run] * 4).astype(np.int32)  # 2 bits of sub-pixel precision
            cv2.polylines(image, [points.reshape(-1, 1, 2)], False, colour, thickness, cv2.LINE_AA, shift=2)


def _densify(polygon: NDArray[np.float64]) -> NDArray[np.float64]:
    closed = np.vstack([polygon, polygon[:1]])
    parts = []
    for a, b in zip(closed[:-1], closed[1:], strict=True):
        n = max(2, int(np.linalg.norm(b - a) / SAMPLE_M) + 1)
        parts.append(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
    return np.vstack(parts)


def _labels(
    image: Image, camera: Camera, xs: NDArray[np.float64], ys: NDArray[np.float64], spacing_m: float, every: int, thickness: int
) -> None:
    step = spacing_m * max(1, every)
    keep_x = xs[np.isclose(np.round(xs / step) * step, xs)]
    keep_y = ys[np.isclose(np.round(ys / step) * step, ys)]
    if not len(keep_x) or not len(keep_y):
        return
    gx, gy = np.meshgrid(keep_x, keep_y)
    crossings = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    pixels = camera.project(crossings)
    scale = 0.35 * thickness
    for (x, y, _), pixel in zip(crossings, pixels, strict=True):
        if not (np.isfinite(pixel).all() and camera.in_image(pixel[None])[0]):
            continue
        u, v = (int(round(c)) for c in pixel)
        cv2.circle(image, (u, v), 2 * thickness, LABEL, -1, cv2.LINE_AA)
        cv2.putText(image, f"{x:g},{y:g}", (u + 3 * thickness, v - 3 * thickness), cv2.FONT_HERSHEY_SIMPLEX, scale, LABEL, 1, cv2.LINE_AA)
