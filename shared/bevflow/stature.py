"""A person's head height measured from their box, for telling people apart (``Cylinders.stature``).

The cylinder fit (``bevflow.cylinder``) picks a height from a grid of three (1.5, 1.7, 1.9 m):
enough to place the feet, but every person of CMC2's real boxes comes out at 1.64–1.70 m. Yet a
box whose feet are known measures more: the head is where a point above the feet meets the box's
edge. On CMC2 (four side cameras 2.15 m up, a real detector's boxes) heights measured so differ
between people by 0.06 m (medians 1.55–1.79 m), while one person's interquartile spread is
0.02–0.14 m; the tracks use that to keep two people apart as they pass
(``bevflow.tracking.stature``).

A view is measured only where that is sound: a strong, unoccluded fit (a box cut at the feet or
rebuilt from the head measures nothing), a head whose image moves mostly along one axis of the
box as its height changes (a side camera's top edge; not a ceiling camera's diagonal), fast
enough that the box's own error (``box_fraction`` of its size) is at most ``max_std_m`` of
height, a head seen from near level (``MAX_DEPRESSION_DEG``: not from a ceiling), and a height
within ``HEIGHTS_M``. The fitted feet's own error carries into the height:
a side camera's box fitted 0.1 m short in range reads a head some 0.05 m off.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera
from bevflow.cylinder import ProjectionMethod
from bevflow.detections import Boxes, Cylinders
from bevflow.fusion import PositionNoise

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

HEIGHTS_M = (1.0, 2.2)
"""The head heights tried, m: a measurement at either end is out of range and dropped."""

STEPS_M = (0.1, 0.01)
"""The search's steps: every 0.1 m over ``HEIGHTS_M``, then every 0.01 m around the best (a third
of the points one pass of 0.01 m projects, and the same heights on CMC2)."""

PROBE_M = 1.7
"""The height at which the head's image motion is measured (which box edge, how fast)."""

AXIS_SHARE = 0.9
"""How much of the head's image motion must lie along one axis for that box edge to measure it."""

MAX_DEPRESSION_DEG = 20.0
"""The steepest a camera may look down at a head (at ``PROBE_M``) and still measure it. CMC2's
side cameras see every head they measure within 16° of level; the paper suite's ceiling cameras
see theirs from 20–82° above, and measuring those cost its rows with the shipped detectors
(seq 6 MOTA 0.903 → 0.894, F1 0.955 → 0.949; MOTA lower on 13 of 17 rows, higher on one by
0.002). Why was not traced; presumably a detector's box of someone seen from above ends at their
head less reliably than a side view's top edge."""


def measure_stature(camera: Camera, boxes: Boxes, cylinders: Cylinders,
                    box_fraction: float = PositionNoise.box_fraction, max_std_m: float = 0.08) -> FloatArray:  # fmt: skip
    """Each fit's head height, m, from its box (``boxes`` and ``cylinders`` row for row, one
    camera); NaN where the box does not measure it (module docstring)."""
    if len(boxes) != len(cylinders):
        raise ValueError(f"{len(boxes)} boxes but {len(cylinders)} cylinders: they go row for row")
    stature = np.full(len(cylinders), np.nan)
    fitted = (cylinders.score > 0) & ~cylinders.occluded & np.isfinite(cylinders.xy).all(axis=1)
    rows = np.flatnonzero(fitted & _seen_from_near_level(camera, cylinders.xy))
    axis, edge, usable = _head_edges(camera, boxes.xyxy[rows], cylinders.xy[rows], box_fraction, max_std_m)
    rows, axis, edge = rows[usable], axis[usable], edge[usable]  # only these are searched
    if not len(rows):
        return stature
    best = _search(camera, cylinders.xy[rows], axis, edge)
    low, high = HEIGHTS_M
    inside = (best > low + 1e-9) & (best < high - 1e-9)
    stature[rows[inside]] = np.round(best[inside], 2)
    return stature


def with_stature(camera: Camera, boxes: Boxes, cylinders: Cylinders, method: ProjectionMethod) -> Cylinders:
    """``cylinders`` placed by ``method`` from ``boxes`` (row for row), with their head heights
    measured where that method fitted the feet (the cylinder fit), as the projector gives them.
    The paper's baselines place the feet at a box point, under a fisheye often 0.2 m off, which
    reads a wrong height: measured before ``MAX_DEPRESSION_DEG`` left ceiling views out, their
    rows of the paper suite's short runs lost up to 0.16 MOTA."""
    if method != "cylinder":
        return cylinders
    return replace(cylinders, stature=measure_stature(camera, boxes, cylinders))


def _head_edges(camera: Camera, xyxy: FloatArray, xy: FloatArray, box_fraction: float,
                max_std_m: float) -> tuple[IntArray, FloatArray, NDArray[np.bool_]]:  # fmt: skip
    """For each box and its feet: the image axis the head moves along, the box edge it moves
    towards, and whether that edge can measure it (the motion clear and fast enough)."""
    n = len(xy)
    probe = _head_image(camera, xy, np.tile([PROBE_M - 0.01, PROBE_M + 0.01], (n, 1)))
    motion = (probe[:, 1] - probe[:, 0]) / 0.02  # px per metre of height
    axis = np.argmax(np.abs(motion), axis=1)
    along = np.abs(motion[np.arange(n), axis])
    # The edge the head moves towards: top (y0) when it rises in the image, and so on.
    rising = motion[np.arange(n), axis] < 0
    edge = np.where(rising, xyxy[np.arange(n), axis], xyxy[np.arange(n), axis + 2])
    extent = xyxy[np.arange(n), axis + 2] - xyxy[np.arange(n), axis]
    with np.errstate(divide="ignore", invalid="ignore"):
        clear = along >= AXIS_SHARE * np.linalg.norm(motion, axis=1)
        precise = box_fraction * extent / along <= max_std_m
    return axis, edge, clear & precise


def _seen_from_near_level(camera: Camera, xy: FloatArray) -> NDArray[np.bool_]:
    """Whether the camera looks down at a head at ``PROBE_M`` above each feet by at most
    ``MAX_DEPRESSION_DEG``: tested first, so a ceiling camera projects nothing."""
    centre = camera.center
    with np.errstate(invalid="ignore"):
        depression = np.degrees(np.arctan2(centre[2] - PROBE_M, np.linalg.norm(xy - centre[:2], axis=1)))
        level: NDArray[np.bool_] = depression <= MAX_DEPRESSION_DEG
    return level


def _search(camera: Camera, xy: FloatArray, axis: IntArray, edge: FloatArray) -> FloatArray:
    """The height in ``HEIGHTS_M`` whose image above each feet lies nearest its edge, found in
    ``STEPS_M``."""
    n = len(xy)
    low, high = HEIGHTS_M
    best, span = np.full(n, (low + high) / 2), high - low
    for step in STEPS_M:
        heights = np.clip(best[:, None] + np.arange(-span / 2, span / 2 + step / 2, step)[None], low, high)
        image = _head_image(camera, xy, heights)[np.arange(n), :, axis]  # (n, heights): along the axis
        with np.errstate(invalid="ignore"):
            miss = np.where(np.isfinite(image), np.abs(image - edge[:, None]), np.inf)
        best, span = heights[np.arange(n), np.argmin(miss, axis=1)], 2 * step
    return best


def _head_image(camera: Camera, xy: FloatArray, heights: FloatArray) -> FloatArray:
    """(n, k, 2) image points of heights (n, k) above each feet (n, 2)."""
    n, k = heights.shape
    points = np.concatenate([np.repeat(xy, k, axis=0), heights.reshape(-1, 1)], axis=1)
    return camera.project(points).reshape(n, k, 2)
