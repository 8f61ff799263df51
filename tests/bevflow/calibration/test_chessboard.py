"""The board: parsing its size, its corner layout, drawing it through a fisheye and finding it again."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import bevflow.calibration.chessboard
from bevflow.calibration.chessboard import BoardRenderer, Chessboard, board_pose_facing
from tests.bevflow.calibration.boards import BOARD, FISHEYE, rendered_images


@pytest.mark.parametrize(
    ("text", "expected"),
    [("9x6", (9, 6)), ("7X5", (7, 5)), (" 10 x 7 ", (10, 7)), ("8×6", (8, 6))],
)
def test_parse(text: str, expected: tuple[int, int]) -> None:
    board = Chessboard.parse(text, 0.025)
    assert board.pattern_size == expected and board.square_m == 0.025


@pytest.mark.parametrize(
    ("text", "square", "message"),
    [("9", 0.03, "COLSxROWS"), ("axb", 0.03, "COLSxROWS"), ("9x2", 0.03, "at least 3x3"), ("9x6", 0.0, "square"), ("9x6", float("nan"), "square")],
)
def test_parse_rejects(text: str, square: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Chessboard.parse(text, square)


def test_object_points_are_row_by_row() -> None:
    points = Chessboard(4, 3, 0.5).object_points()
    assert points.shape == (12, 3)
    np.testing.assert_allclose(points[:5], [[0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [1.5, 0, 0], [0, 0.5, 0]])
    assert (points[:, 2] == 0).all()


def test_pose_facing_puts_the_centre_where_asked() -> None:
    R, t = board_pose_facing((0.0, 0.6, 0.8), 0.5, BOARD, tilt_deg=(0.0, 0.0))
    centre = np.array([(BOARD.cols - 1) / 2, (BOARD.rows - 1) / 2, 0.0]) * BOARD.square_m
    np.testing.assert_allclose(R @ centre + t, [0.0, 0.3, 0.4], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [0.0, 0.6, 0.8], atol=1e-12)  # the board faces the camera
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)


def test_found_corners_match_the_drawn_ones() -> None:
    """Corners found in fisheye images (even near the rim) lie within a fraction of a pixel of
    where the model puts them; the detector may number them from the opposite corner."""
    for image, truth in rendered_images(FISHEYE, 4, seed=5):
        found = BOARD.find_corners(image)
        assert found is not None
        error = min(np.abs(found - truth).max(), np.abs(found[::-1] - truth).max())
        assert error < 0.5


def test_an_image_without_the_board_gives_none() -> None:
    blank = np.full((480, 640), 128, np.uint8)
    assert BOARD.find_corners(blank) is None


def test_render_draws_squares_and_margin_only_where_the_board_is() -> None:
    R, t = board_pose_facing((0.0, 0.0, 1.0), 0.5, BOARD)
    image = BoardRenderer(FISHEYE, BOARD).render(R, t)
    assert image.shape == (640, 640) and image.dtype == np.uint8
    assert image[0, 0] == 128 and image[639, 639] == 128  # background far from the board
    centre = np.round(FISHEYE.project_directions((np.array([[0.5, 0.5, 0.0]]) * BOARD.square_m) @ R.T + t)[0]).astype(int)
    assert image[centre[1], centre[0]] in (20, 235)  # inside a square: black or white, not grey


def test_doctests() -> None:
    assert doctest.testmod(bevflow.calibration.chessboard).failed == 0
