"""Lens calibration recovers a known lens from board views, and drops the views that would spoil it.

Tolerances (0.1 px corner noise, 14 views; measured over six seeds, with about 2x margin):
fisheye fx, fy within 0.5 %, cx, cy within 1 px, and the two lenses image every direction up to
70° off axis within 0.8 px; pinhole fx, fy within 0.6 %, cx, cy within 2.5 px.
"""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.calibration.chessboard import BoardRenderer, board_pose_facing
from bevflow.calibration.intrinsics import MIN_VIEWS, BoardView, CalibrationError, calibrate_intrinsics
from bevflow.camera import Camera
from tests.bevflow.calibration.boards import BOARD, FISHEYE, PINHOLE, projected_views, projection_gap_px, rendered_images


def assert_lens_close(found: Camera, truth: Camera, f_rel: float, c_px: float) -> None:
    np.testing.assert_allclose(np.diag(found.K)[:2], np.diag(truth.K)[:2], rtol=f_rel)
    np.testing.assert_allclose(found.K[:2, 2], truth.K[:2, 2], atol=c_px)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fisheye_is_recovered(seed: int) -> None:
    result = calibrate_intrinsics(projected_views(FISHEYE, 14, 0.1, seed), BOARD, FISHEYE.image_size)
    assert result.model == "fisheye" and result.dist.shape == (4,) and not result.dropped
    assert_lens_close(result.camera(), FISHEYE, f_rel=0.005, c_px=1.0)
    assert projection_gap_px(result.camera(), FISHEYE, 70.0) < 0.8
    assert 0.1 < result.rms_px < 0.2  # 0.1 px per coordinate is 0.14 px per corner
    assert result.max_angle_deg > 70.0
    assert len(result.view_rms_px) == 14 and max(result.view_rms_px.values()) < 0.25


@pytest.mark.parametrize("seed", [0, 1])
def test_pinhole_is_recovered(seed: int) -> None:
    result = calibrate_intrinsics(projected_views(PINHOLE, 14, 0.1, seed), BOARD, PINHOLE.image_size, model="pinhole")
    assert result.dist.shape == (5,)
    assert_lens_close(result.camera(), PINHOLE, f_rel=0.006, c_px=2.5)
    np.testing.assert_allclose(result.dist[:2], PINHOLE.dist[:2], atol=0.02)


def test_from_rendered_images() -> None:
    """The whole path: images drawn through the lens, corners found, lens calibrated."""
    views = []
    for k, (image, _) in enumerate(rendered_images(FISHEYE, 10, seed=7)):
        corners = BOARD.find_corners(image)
        views.append(BoardView(f"img{k}", corners if corners is not None else np.zeros((0, 2))))
    result = calibrate_intrinsics(views, BOARD, FISHEYE.image_size)
    assert len(result.view_rms_px) >= 8
    assert_lens_close(result.camera(), FISHEYE, f_rel=0.005, c_px=1.5)
    assert projection_gap_px(result.camera(), FISHEYE, 70.0) < 1.0
    assert result.rms_px < 0.3


def test_bad_views_are_dropped_with_reasons() -> None:
    views = projected_views(FISHEYE, 12, 0.1, seed=3)
    views[2] = BoardView("misdetected", views[2].corners + np.where(np.arange(len(BOARD))[:, None] % 7 == 0, 6.0, 0.0))
    views[5] = BoardView("half-board", views[5].corners[:20])
    result = calibrate_intrinsics(views, BOARD, FISHEYE.image_size)
    reasons = dict(result.dropped)
    assert set(reasons) == {"misdetected", "half-board"}
    assert "far above the others" in reasons["misdetected"] and "20 corners" in reasons["half-board"]
    assert_lens_close(result.camera(), FISHEYE, f_rel=0.005, c_px=1.0)


def test_a_board_at_the_very_rim_is_dropped() -> None:
    """OpenCV cannot start from a board reaching ~90° off axis; the view goes, the rest calibrate."""
    views = projected_views(FISHEYE, 10, 0.1, seed=4)
    R, t = board_pose_facing((0.985, 0.0, 0.174), 0.5, BOARD, tilt_deg=(-60.0, -60.0))  # out to 87°
    rim = BoardRenderer(FISHEYE, BOARD).corners(R, t)
    assert FISHEYE.in_image(rim).all()
    result = calibrate_intrinsics([*views, BoardView("rim", rim)], BOARD, FISHEYE.image_size)
    assert "rim" in dict(result.dropped)
    assert_lens_close(result.camera(), FISHEYE, f_rel=0.005, c_px=1.0)


@pytest.mark.parametrize("usable", [0, 2, MIN_VIEWS - 1])
def test_too_few_views(usable: int) -> None:
    views = projected_views(FISHEYE, usable, 0.1, seed=1) + [BoardView("empty", np.zeros((0, 2)))]
    with pytest.raises(CalibrationError, match=f"only {usable} usable board views"):
        calibrate_intrinsics(views, BOARD, FISHEYE.image_size)
