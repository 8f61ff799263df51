"""Where in a frame the detector needs to look: the window of the image that holds everyone whose
detections the projector keeps.

The projector uses a camera's detections only within its reporting radius (the monitored radius
plus a margin, ``CameraConfig.reporting_radius_m``): beyond it a fisheye's people are too small
and oblique to place. A ceiling fisheye's image circle shows the floor out to the horizon, so most
of its pixels lie past that radius: at 5.5 m with an 8 m radius, a person standing on the circle
reaches 67° from the axis of a 90° half-view, so the square around the region is 0.75 of the
image across and holds 56 % of its pixels; at 8.1 m with a 10 m radius, 44 %. Running the
detector on that window alone costs about that share of the whole frame's time (the network is
fully convolutional), and finds the same people inside it.

The window is the bounding box of the projections of bodies standing anywhere on the reporting
disk: the disk widened by a body's half width, sampled from the floor up to the top of a head,
padded by a few pixels and clipped to the image. Points the camera cannot see (behind a
side-view camera) are left out.

>>> from bevflow.camera import FisheyeCamera
>>> cam = FisheyeCamera.looking_down((0.0, 0.0, 5.5), (1280, 1280))
>>> x0, y0, x1, y1 = detection_window(cam, 8.5)
>>> 0 < x0 < 640 < x1 < 1280 and (x1 - x0) < 0.8 * 1280
True
>>> detection_window(cam, None) is None
True
"""

from __future__ import annotations

import math

import numpy as np

from bevflow.camera import Camera

BODY_TOP_M = 2.0  # above the tallest head the simulator or a site holds (1.95 m)
BODY_HALF_WIDTH_M = 0.35  # shoulders and arms reach this far from the feet on the floor plan
PAD_PX = 4
_ANGLES = 180
_RINGS = 9
_HEIGHTS = (0.0, 0.5 * BODY_TOP_M, BODY_TOP_M)

Window = tuple[int, int, int, int]


def detection_window(camera: Camera, radius_m: float | None, pad_px: int = PAD_PX) -> Window | None:
    """(x0, y0, x1, y1): the pixels [x0, x1) × [y0, y1) of ``camera``'s calibrated image that
    hold every body whose feet lie within ``radius_m`` of the point below the camera. None when
    there is no radius (the whole image) or the camera sees none of the region."""
    if radius_m is None:
        return None
    if not radius_m > 0:
        raise ValueError(f"radius_m must be > 0, got {radius_m}")
    reach = radius_m + BODY_HALF_WIDTH_M
    angle = np.linspace(0.0, 2.0 * math.pi, _ANGLES, endpoint=False)
    ring = np.linspace(0.0, reach, _RINGS)
    height = np.asarray(_HEIGHTS)
    r, a, z = (g.ravel() for g in np.meshgrid(ring, angle, height, indexing="ij"))
    centre = camera.center
    points = np.column_stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a), z])
    pixels = camera.project(points)
    pixels = pixels[np.isfinite(pixels).all(axis=1)]
    if not len(pixels):
        return None
    w, h = camera.image_size
    x0, y0 = np.floor(pixels.min(axis=0)).astype(int) - pad_px
    x1, y1 = np.ceil(pixels.max(axis=0)).astype(int) + 1 + pad_px
    x0, x1 = int(np.clip(x0, 0, w)), int(np.clip(x1, 0, w))
    y0, y1 = int(np.clip(y0, 0, h)), int(np.clip(y1, 0, h))
    return None if x1 <= x0 or y1 <= y0 else (x0, y0, x1, y1)


def scaled_window(window: Window | None, scale: float, frame_width: int, frame_height: int) -> Window:
    """``window`` (calibrated pixels) in a frame resized by ``scale``, grown to whole pixels and
    clipped to the frame; the whole frame for None."""
    if window is None:
        return (0, 0, frame_width, frame_height)
    x0, y0, x1, y1 = window
    return (
        max(0, math.floor(x0 * scale)),
        max(0, math.floor(y0 * scale)),
        min(frame_width, math.ceil(x1 * scale)),
        min(frame_height, math.ceil(y1 * scale)),
    )
