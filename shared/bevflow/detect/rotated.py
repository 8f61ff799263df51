"""Rotated boxes, as overhead fisheye datasets annotate people: (cx, cy, w, h, degrees).

The convention is CEPDOF's, WEPDTOF's and RAPiD's, and OpenCV's ``boxPoints``: the box is w
wide and h tall before it is turned by ``degrees`` clockwise on screen (image y points down)
about its centre. In a ceiling fisheye a person lies along the radius through the image centre,
so a person's box has its height along the radius: its *radial angle* is the one that turns the
box's up axis toward the centre (0 below the centre, 90 to its left). A box turned half a turn
more is the same rectangle (with its up axis outward, where a person's head is).

IoU between rotated boxes is computed exactly: the intersection of two convex quadrilaterals by
clipping one against the other's edges (Sutherland–Hodgman), in numpy, without shapely.

>>> round(float(rotated_iou_matrix(np.array([[0, 0, 2, 2, 0]]), np.array([[1, 0, 2, 2, 0]]))[0, 0]), 4)
0.3333
>>> round(float(rotated_iou_matrix(np.array([[0, 0, 2, 2, 0]]), np.array([[0, 0, 2, 2, 45]]))[0, 0]), 4)
0.7071
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bevflow.detect.coco import rotated_to_xyxy

FloatArray = NDArray[np.float64]

# Near 45° an axis-aligned box fits a whole family of rotated boxes equally well (see
# ``radial_boxes``); from |cos 2a| below this the exact solution gives way to a square.
_SINGULAR_COS2A = 0.4
_MIN_SIDE_PX = 1.0


def outline_xyxy(rotated: FloatArray) -> FloatArray:
    """(N, 5) rotated boxes → (N, 4) the axis-aligned box of the ellipse inscribed in each: the
    upright box of a person lying in the rotated box, who fills its sides but not its corners.

    The enclosing box of the rectangle (``rotated_to_xyxy``) reaches into its corners, which a
    body does not fill: for a box three times as tall as wide at 45° it is 60 % larger. The
    cylinder fit places the feet from the upright box's point nearest the image centre
    (``bevflow.cylinder``), so those corners move people toward the camera. At 0° and 90° the
    two are the same box."""
    r = np.asarray(rotated, np.float64).reshape(-1, 5)
    a = np.radians(r[:, 4])
    c, s = np.cos(a), np.sin(a)
    hw = np.hypot(c * r[:, 2], s * r[:, 3]) / 2
    hh = np.hypot(s * r[:, 2], c * r[:, 3]) / 2
    return np.stack([r[:, 0] - hw, r[:, 1] - hh, r[:, 0] + hw, r[:, 1] + hh], axis=1)


def rotated_corners(rotated: FloatArray) -> FloatArray:
    """(N, 5) rotated boxes → (N, 4, 2) corners, counter-clockwise on screen."""
    r = np.asarray(rotated, np.float64).reshape(-1, 5)
    a = np.radians(r[:, 4])
    c, s = np.cos(a), np.sin(a)
    local = np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, 0.5], [0.5, -0.5]])
    lx = local[None, :, 0] * r[:, 2:3]
    ly = local[None, :, 1] * r[:, 3:4]
    x = r[:, 0:1] + c[:, None] * lx - s[:, None] * ly
    y = r[:, 1:2] + s[:, None] * lx + c[:, None] * ly
    return np.stack([x, y], axis=2)


def polygon_area(poly: FloatArray) -> float:
    """Area of a simple polygon (K, 2), whatever its orientation (shoelace formula)."""
    return abs(_signed_area([(float(x), float(y)) for x, y in np.asarray(poly, np.float64).reshape(-1, 2)]))


def _signed_area(pts: list[tuple[float, float]]) -> float:
    if len(pts) < 3:
        return 0.0
    return 0.5 * sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(pts, pts[1:] + pts[:1], strict=True))


def convex_intersection(subject: FloatArray, clip: FloatArray) -> FloatArray:
    """The intersection of two convex polygons (K, 2), as a polygon (possibly empty)."""
    return np.array(_clip(_points(subject), _points(clip)), dtype=np.float64).reshape(-1, 2)


def _points(polygon: FloatArray) -> list[tuple[float, float]]:
    return [(float(x), float(y)) for x, y in np.asarray(polygon, np.float64).reshape(-1, 2)]


def _clip(out: list[tuple[float, float]], clip: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Sutherland–Hodgman on plain Python floats: for quadrilaterals several times faster than
    numpy, whose per-call cost dominates arrays of four points."""
    orientation = 1.0 if _signed_area(clip) >= 0 else -1.0
    for i in range(len(clip)):
        if not out:
            break
        (px, py), (qx, qy) = clip[i], clip[(i + 1) % len(clip)]
        # Inside = on the interior side of the directed edge p→q, whichever way ``clip`` winds.
        side = [orientation * ((qx - px) * (y - py) - (qy - py) * (x - px)) for x, y in out]
        kept = []
        for j in range(len(out)):
            (ax, ay), (bx, by) = out[j], out[(j + 1) % len(out)]
            sa, sb = side[j], side[(j + 1) % len(out)]
            if sa >= 0:
                kept.append((ax, ay))
            if (sa >= 0) != (sb >= 0):
                t = sa / (sa - sb)
                kept.append((ax + (bx - ax) * t, ay + (by - ay) * t))
        out = kept
    return out


def rotated_iou_matrix(a: FloatArray, b: FloatArray) -> FloatArray:
    """(P, 5) × (Q, 5) rotated boxes → (P, Q) intersection over union. Pairs whose enclosing
    axis-aligned boxes do not touch are 0 without clipping (most pairs in a frame)."""
    a, b = np.asarray(a, np.float64).reshape(-1, 5), np.asarray(b, np.float64).reshape(-1, 5)
    out = np.zeros((len(a), len(b)))
    if not len(a) or not len(b):
        return out
    ea, eb = rotated_to_xyxy(a), rotated_to_xyxy(b)
    touch = (
        (ea[:, None, 0] < eb[None, :, 2]) & (eb[None, :, 0] < ea[:, None, 2])
        & (ea[:, None, 1] < eb[None, :, 3]) & (eb[None, :, 1] < ea[:, None, 3])
    )  # fmt: skip
    ca, cb = rotated_corners(a).tolist(), rotated_corners(b).tolist()
    area_a, area_b = a[:, 2] * a[:, 3], b[:, 2] * b[:, 3]
    for i, j in zip(*np.nonzero(touch), strict=True):
        inter = abs(_signed_area(_clip([tuple(p) for p in ca[i]], [tuple(p) for p in cb[j]])))
        out[i, j] = inter / max(area_a[i] + area_b[j] - inter, 1e-12)
    return out


def radial_angle(cx: FloatArray, cy: FloatArray, centre: tuple[float, float]) -> FloatArray:
    """Degrees that turn a box at (cx, cy) so its height runs along the radius from ``centre``."""
    return np.degrees(np.arctan2(-(np.asarray(cx) - centre[0]), np.asarray(cy) - centre[1]))


def radial_boxes(xyxy: FloatArray, centre: tuple[float, float]) -> FloatArray:
    """Axis-aligned boxes → rotated boxes at their radial angle about ``centre``, sized so that
    their enclosing axis-aligned box is the given one (an upright detector boxes a person lying
    along the radius by that enclosing box). Solving for the sides is exact away from 45°; near
    45° every split of the box into width and height fits equally, so the sides blend into a
    square there rather than jump between extremes."""
    x = np.asarray(xyxy, np.float64).reshape(-1, 4)
    cx, cy = (x[:, 0] + x[:, 2]) / 2, (x[:, 1] + x[:, 3]) / 2
    bw, bh = x[:, 2] - x[:, 0], x[:, 3] - x[:, 1]
    deg = radial_angle(cx, cy, centre)
    c, s = np.abs(np.cos(np.radians(deg))), np.abs(np.sin(np.radians(deg)))
    det = c * c - s * s  # cos 2a
    safe = np.where(np.abs(det) < 1e-9, 1e-9, det)
    w_exact, h_exact = (c * bw - s * bh) / safe, (c * bh - s * bw) / safe
    side = (bw + bh) / (2 * (c + s))  # the square whose enclosing box has this size
    t = np.clip(np.abs(det) / _SINGULAR_COS2A, 0.0, 1.0)
    w = np.maximum(t * w_exact + (1 - t) * side, _MIN_SIDE_PX)
    h = np.maximum(t * h_exact + (1 - t) * side, _MIN_SIDE_PX)
    return np.stack([cx, cy, w, h, deg], axis=1)
