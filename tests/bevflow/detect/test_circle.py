"""Finding a fisheye frame's image circle, and what is assumed of a frame without calibration."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bevflow.detect.circle import DEFAULT_CEILING_M, assume_calibration, find_image_circle


def _fisheye(size: tuple[int, int], centre: tuple[int, int], radius: int, seed: int = 0) -> np.ndarray:
    """A textured bright disc on black, like a fisheye frame's scene inside its image circle."""
    w, h = size
    rng = np.random.default_rng(seed)
    scene = rng.integers(40, 230, (h // 8 + 1, w // 8 + 1, 3), dtype=np.uint8)
    scene = cv2.resize(scene, (w, h), interpolation=cv2.INTER_NEAREST)[:h, :w]
    mask = np.zeros((h, w), np.uint8)
    cv2.circle(mask, centre, radius, 255, -1)
    return np.where(mask[..., None] > 0, scene, 0).astype(np.uint8)


@pytest.mark.parametrize(
    ("size", "centre", "radius"),
    [
        ((800, 800), (400, 400), 380),  # a square frame, circle inside
        ((1000, 800), (480, 410), 350),  # off centre
        ((1920, 1080), (960, 540), 700),  # a 16:9 sensor cuts the circle at top and bottom
        ((2048, 2048), (1024, 1024), 1026),  # the circle just cut by all four edges
    ],
)
def test_finds_the_circle(size: tuple[int, int], centre: tuple[int, int], radius: int) -> None:
    c = find_image_circle(_fisheye(size, centre, radius))
    assert c.found
    assert (c.cx, c.cy) == pytest.approx(centre, abs=0.01 * radius + 2)
    assert c.radius == pytest.approx(radius, rel=0.01)


def test_dark_things_at_the_rim_and_text_on_the_border_do_not_move_it() -> None:
    frame = _fisheye((1200, 1200), (600, 600), 560)
    for angle in (20, 150, 260):  # dark furniture or clothing where the scene meets the border
        x, y = 600 + 540 * math.cos(math.radians(angle)), 600 + 540 * math.sin(math.radians(angle))
        cv2.circle(frame, (round(x), round(y)), 60, (5, 5, 5), -1)
    cv2.putText(frame, "13:00:0557", (5, 50), cv2.FONT_HERSHEY_SIMPLEX, 1.6, (255, 255, 255), 4)  # burnt-in time
    c = find_image_circle(frame)
    assert c.found and (c.cx, c.cy) == pytest.approx((600, 600), abs=6) and c.radius == pytest.approx(560, rel=0.015)


@pytest.mark.parametrize("frame", [np.full((300, 400, 3), 128, np.uint8), np.zeros((300, 400, 3), np.uint8)])
def test_a_frame_without_a_dark_border_is_assumed_to_fill_it(frame: np.ndarray) -> None:
    c = find_image_circle(frame)
    assert not c.found
    assert (c.cx, c.cy, c.radius) == pytest.approx((199.5, 149.5, 250.0))


def test_assumed_calibration_takes_the_focal_length_from_the_circle() -> None:
    a = assume_calibration(_fisheye((800, 800), (400, 400), 380))
    assert a.camera_height_m == DEFAULT_CEILING_M
    assert a.focal_px == pytest.approx(a.circle.radius / math.radians(95))
    assert a.focal_px == pytest.approx(380 / math.radians(95), rel=0.01)
    assert assume_calibration(_fisheye((800, 800), (400, 400), 380), 4.0, 180).focal_px == pytest.approx(2 * a.circle.radius / math.pi)
    assert "190° equidistant lens" in a.describe() and "3 m above the floor" in a.describe()


def test_a_field_of_view_out_of_reason_is_refused() -> None:
    with pytest.raises(ValueError, match="field of view"):
        assume_calibration(np.zeros((10, 10, 3), np.uint8), field_of_view_deg=30)
