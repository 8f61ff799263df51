"""The detector's window: the part of a frame that shows everyone the projector keeps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.detect.window import detection_window, scaled_window


def body_points(camera, radius_m: float, rng: np.random.Generator, n: int = 2000) -> np.ndarray:
    """Points of bodies whose feet stand anywhere within ``radius_m`` of the point below the camera."""
    r = radius_m * np.sqrt(rng.uniform(0, 1, n))
    a = rng.uniform(0, 2 * math.pi, n)
    feet = camera.center[:2] + np.column_stack([r * np.cos(a), r * np.sin(a)])
    offset = rng.uniform(-0.3, 0.3, (n, 2))  # shoulders and arms
    return np.column_stack([feet + offset, rng.uniform(0, 1.95, n)])


@pytest.mark.parametrize(
    ("height_m", "radius_m", "largest_share"),
    [(3.3, 4.0, 0.70), (5.5, 8.5, 0.60), (8.1, 10.5, 0.50)],  # the paper's three mounting heights
)
def test_the_window_holds_every_body_on_the_disk_and_leaves_out_the_rim(height_m, radius_m, largest_share) -> None:
    camera = FisheyeCamera.looking_down((2.0, 3.0, height_m), (1280, 1280))
    x0, y0, x1, y1 = detection_window(camera, radius_m)
    pixels = camera.project(body_points(camera, radius_m, np.random.default_rng(0)))
    assert ((pixels >= [x0, y0]) & (pixels < [x1, y1])).all()
    assert (x1 - x0) * (y1 - y0) < largest_share * 1280 * 1280
    # the floor near the horizon, 80 degrees off the axis, is left out
    far = camera.project(np.array([[camera.center[0] + height_m * math.tan(math.radians(80.0)), camera.center[1], 0.0]]))
    assert far[0, 0] >= x1


def test_a_radius_past_the_horizon_gives_the_image_circle_of_the_floor() -> None:
    camera = FisheyeCamera.looking_down((0.0, 0.0, 3.3), (1280, 1280), fov_deg=180.0)
    x0, y0, x1, y1 = detection_window(camera, 1000.0)
    assert x0 == y0 == 0 and x1 == y1 == 1280


def test_a_side_view_keeps_what_it_sees_of_the_disk() -> None:
    R = rotation_from_ypr(0.0, -20.0, 0.0)
    K = np.array([[1000.0, 0, 959.5], [0, 1000.0, 539.5], [0, 0, 1]])
    camera = PinholeCamera(K=K, dist=np.zeros(5), R=R, t=-R @ np.array([0.0, 0.0, 3.0]), image_size=(1920, 1080))
    window = detection_window(camera, 10.0)
    assert window is not None and window[2] <= 1920 and window[3] <= 1080
    pixels = camera.project(body_points(camera, 10.0, np.random.default_rng(1)))
    seen = np.isfinite(pixels).all(axis=1) & (pixels >= 0).all(axis=1) & (pixels < [1920, 1080]).all(axis=1)
    assert ((pixels[seen] >= window[:2]) & (pixels[seen] < window[2:])).all()


@pytest.mark.parametrize("radius_m", [0.0, -1.0])
def test_the_radius_must_be_positive(radius_m: float) -> None:
    with pytest.raises(ValueError, match="radius_m"):
        detection_window(FisheyeCamera.looking_down((0.0, 0.0, 3.3), (640, 640)), radius_m)


@pytest.mark.parametrize(
    ("window", "scale", "frame", "expected"),
    [
        (None, 0.5, (400, 300), (0, 0, 400, 300)),  # no window: the whole frame
        ((100, 50, 700, 551), 1.0, (800, 600), (100, 50, 700, 551)),
        ((101, 51, 701, 551), 0.5, (400, 300), (50, 25, 351, 276)),  # grown to whole pixels
        ((0, 0, 800, 600), 0.5, (399, 299), (0, 0, 399, 299)),  # clipped to the frame
    ],
)
def test_scaled_window(window, scale, frame, expected) -> None:
    assert scaled_window(window, scale, *frame) == expected
