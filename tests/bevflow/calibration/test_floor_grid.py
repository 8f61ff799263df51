"""The floor grid drawn through a camera: lines where the floor's metre lines are, labels at the
crossings, zones outlined, nothing between the lines."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.calibration.floor_grid import AXIS, BACKGROUND, GRID, ZONE, floor_extent, render_floor_grid
from bevflow.camera import FisheyeCamera

CAMERA = FisheyeCamera.looking_down((5.0, 4.0, 4.0), (640, 640), 185.0, yaw_deg=20.0)
ZONE_SQUARE = [(6.5, 5.5), (8.5, 5.5), (8.5, 7.5), (6.5, 7.5)]


def pixel_of(x: float, y: float) -> tuple[int, int]:
    u, v = CAMERA.project(np.array([[x, y, 0.0]]))[0]
    return int(round(u)), int(round(v))


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return render_floor_grid(CAMERA, (0.0, 0.0, 10.0, 8.0), zones=[ZONE_SQUARE])


@pytest.mark.parametrize(
    ("floor_xy", "expected"),
    [
        ((3.0, 4.5), GRID),  # on the line x = 3
        ((4.5, 2.0), GRID),  # on the line y = 2
        ((0.0, 3.5), AXIS),  # the Y axis
        ((7.5, 5.5), ZONE),  # the zone's lower edge, drawn over the grid
    ],
)
def test_lines_are_where_the_floor_lines_are(image: np.ndarray, floor_xy: tuple[float, float], expected: tuple[int, int, int]) -> None:
    u, v = pixel_of(*floor_xy)
    patch = image[v - 1 : v + 2, u - 1 : u + 2].reshape(-1, 3).astype(int)
    assert np.abs(patch - np.array(expected)).sum(axis=1).min() < 100  # anti-aliased; other colours are 250 or more away


@pytest.mark.parametrize("floor_xy", [(3.5, 2.5), (6.5, 3.5), (1.5, 6.5)])
def test_nothing_between_the_lines(image: np.ndarray, floor_xy: tuple[float, float]) -> None:
    u, v = pixel_of(*floor_xy)
    assert (image[v, u] == BACKGROUND).all()


def test_crossings_are_labelled_and_the_point_below_marked(image: np.ndarray) -> None:
    u, v = pixel_of(4.0, 4.0)  # an even crossing: a dot and an "x,y" label beside it
    assert image[v - 1 : v + 2, u - 1 : u + 2].min() > 180
    nadir_u, nadir_v = pixel_of(5.0, 4.0)
    assert image[nadir_v, nadir_u, 2] > 200  # red cross below the camera
    assert image.shape == (640, 640, 3) and image.dtype == np.uint8


@pytest.mark.parametrize(
    ("floor", "reach", "expected"),
    [
        (None, None, (-7.0, -8.0, 17.0, 16.0)),  # three heights around the point below
        ((0.0, 0.0, 30.0, 20.0), None, (0.0, 0.0, 17.0, 16.0)),  # clipped to the floor
        ((0.0, 0.0, 30.0, 20.0), 2.0, (3.0, 2.0, 7.0, 6.0)),
        ((40.0, 40.0, 50.0, 50.0), 2.0, (3.0, 2.0, 7.0, 6.0)),  # the floor is elsewhere: the reach alone
    ],
)
def test_floor_extent(floor: tuple | None, reach: float | None, expected: tuple) -> None:
    assert floor_extent(CAMERA, floor, reach) == pytest.approx(expected)


def test_bad_spacing() -> None:
    with pytest.raises(ValueError, match="spacing_m"):
        render_floor_grid(CAMERA, (0.0, 0.0, 1.0, 1.0), spacing_m=0.0)


def test_doctests() -> None:
    import doctest

    import bevflow.calibration.floor_grid

    assert doctest.testmod(bevflow.calibration.floor_grid).failed == 0
