"""A camera's lens from chessboard views: K and the distortion coefficients.

Fisheye cameras go through ``cv2.fisheye.calibrate`` (OpenCV 5 needs an initial K and points
shaped (1, N, k)); pinhole cameras through ``cv2.calibrateCamera`` with (k1, k2, p1, p2, k3).

Views that would spoil the solution are dropped, and each drop is reported with its reason:

- OpenCV's condition check names a view whose board pose cannot be solved (seen too obliquely,
  too small, or nearly degenerate); that view goes and the calibration runs again.
- After a solution, a view whose RMS error is far above the others (``outlier_factor`` × the
  median, and above ``outlier_floor_px``) is a bad detection (a corner snapped to the wrong edge,
  motion blur); it goes, and the calibration runs again.

A lens is only known where the board has been: ``max_angle_deg`` says how far off the optical
axis the corners reached. Ceiling cameras see people's heads 60–65° off axis at the edge of their
monitored circle, so views should reach at least that far.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.calibration.chessboard import Chessboard
from bevflow.camera import FisheyeCamera, PinholeCamera

Array = NDArray[np.float64]
LensModel = Literal["fisheye", "pinhole"]

MIN_VIEWS = 4
RECOMMENDED_VIEWS = 12
RECOMMENDED_ANGLE_DEG = 60.0
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-10)
_FISHEYE_FLAGS = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW | cv2.CALIB_CHECK_COND


class CalibrationError(ValueError):
    """The views cannot give a calibration; ``str()`` says why and what to do."""


@dataclass(frozen=True)
class BoardView:
    """The board's inner corners (N, 2) found in one image, named after where they came from."""

    name: str
    corners: Array


@dataclass(frozen=True)
class IntrinsicsResult:
    """K (3×3) and ``dist`` (4 for fisheye, 5 for pinhole) of ``model``; ``rms_px`` over every
    corner of the views used; ``view_rms_px`` per view used, by name; ``dropped`` (name, reason)."""

    model: LensModel
    K: Array
    dist: Array
    image_size: tuple[int, int]
    rms_px: float
    view_rms_px: dict[str, float]
    dropped: list[tuple[str, str]] = field(default_factory=list)
    max_angle_deg: float = float("nan")

    def camera(self) -> FisheyeCamera | PinholeCamera:
        """The lens as a camera model at the origin, looking along +Z."""
        cls = FisheyeCamera if self.model == "fisheye" else PinholeCamera
        return cls(K=self.K, dist=self.dist, R=np.eye(3), t=np.zeros(3), image_size=self.image_size)


def calibrate_intrinsics(
    views: Sequence[BoardView],
    board: Chessboard,
    image_size: tuple[int, int],
    model: LensModel = "fisheye",
    outlier_factor: float = 3.0,
    outlier_floor_px: float = 1.0,
) -> IntrinsicsResult:
    """Calibrate the lens from ``views`` of ``board`` in images of ``image_size`` (w, h).

    Raises ``CalibrationError`` when fewer than ``MIN_VIEWS`` usable views remain."""
    expected = len(board)
    dropped: list[tuple[str, str]] = []
    usable: list[BoardView] = []
    for view in views:
        corners = np.asarray(view.corners, dtype=np.float64).reshape(-1, 2)
        if len(corners) != expected or not np.isfinite(corners).all():
            dropped.append((view.name, f"{len(corners)} corners, the board has {expected}"))
        else:
            usable.append(BoardView(view.name, corners))
    solve = _solve_fisheye if model == "fisheye" else _solve_pinhole
    while True:
        _require_views(usable, dropped)
        outcome = solve(usable, board, image_size)
        if isinstance(outcome, int):  # the index of an ill-conditioned view
            dropped.append((usable[outcome].name, "board pose ill-conditioned (too oblique, too small or too far)"))
            del usable[outcome]
            continue
        if isinstance(outcome, list):  # views OpenCV cannot even start from
            for k in sorted(outcome, reverse=True):
                dropped.append((usable[k].name, "board too close to the edge of the lens to start from (near 90° off axis)"))
                del usable[k]
            continue
        K, dist, per_view = outcome
        worst = int(np.argmax(per_view))
        limit = max(outlier_factor * float(np.median(per_view)), outlier_floor_px)
        if per_view[worst] > limit and len(usable) > MIN_VIEWS:
            dropped.append((usable[worst].name, f"RMS {per_view[worst]:.2f} px, far above the others (limit {limit:.2f} px)"))
            del usable[worst]
            continue
        break
    rms = float(np.sqrt(np.mean(per_view**2)))  # every view has the same number of corners
    result = IntrinsicsResult(
        model=model,
        K=K,
        dist=dist,
        image_size=(int(image_size[0]), int(image_size[1])),
        rms_px=rms,
        view_rms_px={v.name: float(e) for v, e in zip(usable, per_view, strict=True)},
        dropped=dropped,
    )
    return _with_reach(result, usable)


def _require_views(usable: list[BoardView], dropped: list[tuple[str, str]]) -> None:
    if len(usable) >= MIN_VIEWS:
        return
    hint = f"; {len(dropped)} dropped" if dropped else ""
    raise CalibrationError(
        f"only {len(usable)} usable board views (at least {MIN_VIEWS} are needed, {RECOMMENDED_VIEWS} or more "
        f"recommended{hint}): take more pictures with the whole board in view, at varied angles and across the image"
    )


def _solve_fisheye(
    views: list[BoardView], board: Chessboard, image_size: tuple[int, int]
) -> tuple[Array, Array, Array] | int | list[int]:
    """K, D and per-view RMS; or the index of an ill-conditioned view; or the views that cannot start."""
    w, h = image_size
    # Without a starting K, OpenCV's extrinsic initialisation fails on wide lenses; an equidistant
    # 180° lens filling the image width is close enough for any ceiling fisheye.
    K0 = np.array([[w / math.pi, 0.0, w / 2.0], [0.0, w / math.pi, h / 2.0], [0.0, 0.0, 1.0]])
    # OpenCV 5 rejects (N, 1, k) point arrays here (opencv/opencv#29692); (1, N, k) works.
    objects = [board.object_points().reshape(1, -1, 3)] * len(views)
    images = [v.corners.reshape(1, -1, 2) for v in views]
    try:
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
            objects, images, (w, h), K0, np.zeros(4), flags=_FISHEYE_FLAGS, criteria=_CRITERIA
        )
    except cv2.error as exc:
        bad = _ill_conditioned_view(str(exc))
        if bad is not None:
            return bad
        # Other failures (OpenCV's "norm_u1 > 0" assertion) do not say which view caused them:
        # a board reaching ~90° off axis has no place on the normalised image plane OpenCV starts
        # from. Find such views by trying each one alone.
        failing = [k for k, view in enumerate(views) if not _starts_alone(view, board, image_size, K0)]
        if failing and len(failing) < len(views):
            return failing
        raise CalibrationError(f"the fisheye calibration failed ({_first_line(exc)}); check --board and --model") from None
    D = D.ravel()
    per_view = np.array(
        [
            _rms(cv2.fisheye.projectPoints(objects[0], r, t, K, D)[0].reshape(-1, 2) - v.corners)
            for r, t, v in zip(rvecs, tvecs, views, strict=True)
        ]
    )
    return np.asarray(K, dtype=np.float64), np.asarray(D, dtype=np.float64), per_view


def _starts_alone(view: BoardView, board: Chessboard, image_size: tuple[int, int], K0: Array) -> bool:
    try:
        cv2.fisheye.calibrate(
            [board.object_points().reshape(1, -1, 3)], [view.corners.reshape(1, -1, 2)], tuple(image_size), K0.copy(),
            np.zeros(4), flags=_FISHEYE_FLAGS, criteria=(cv2.TERM_CRITERIA_COUNT, 1, 0.0),
        )
    except cv2.error as exc:
        return _ill_conditioned_view(str(exc)) is not None  # conditioning is judged with the others
    return True


def _solve_pinhole(views: list[BoardView], board: Chessboard, image_size: tuple[int, int]) -> tuple[Array, Array, Array]:
    objects = [board.object_points().astype(np.float32)] * len(views)
    images = [v.corners.astype(np.float32) for v in views]
    try:
        _, K, D, rvecs, tvecs = cv2.calibrateCamera(objects, images, tuple(image_size), None, None, criteria=_CRITERIA)
    except cv2.error as exc:
        raise CalibrationError(f"the pinhole calibration did not converge ({_first_line(exc)}); check the board size") from None
    D = D.ravel()[:5]
    per_view = np.array(
        [
            _rms(cv2.projectPoints(objects[0].astype(np.float64), r, t, K, D)[0].reshape(-1, 2) - v.corners)
            for r, t, v in zip(rvecs, tvecs, views, strict=True)
        ]
    )
    return np.asarray(K, dtype=np.float64), np.asarray(D, dtype=np.float64), per_view


def _ill_conditioned_view(message: str) -> int | None:
    marker = "Ill-conditioned matrix for input array"
    if marker not in message:
        return None
    digits = message.split(marker, 1)[1].strip().split()[0]
    return int(digits) if digits.isdigit() else None


def _with_reach(result: IntrinsicsResult, views: list[BoardView]) -> IntrinsicsResult:
    corners = np.concatenate([v.corners for v in views])
    rays = result.camera().rays(corners)
    angles = np.degrees(np.arccos(np.clip(rays[:, 2], -1.0, 1.0)))
    reach = float(np.nanmax(angles)) if np.isfinite(angles).any() else float("nan")
    return IntrinsicsResult(**{**result.__dict__, "max_angle_deg": reach})


def _rms(residuals: Array) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[-1] if text else type(exc).__name__
