"""The chessboard target: its geometry, finding its corners in an image, and drawing it through a
camera model (for tests, and to show a technician what a good set of views looks like).

A board is named by its *inner* corners, as OpenCV does: a "9x6" board has 10 × 7 squares. Corner
(i, j) lies at (i·square, j·square, 0) in the board's own frame, i along a row (``cols``), in the
order ``find_corners`` returns them.

>>> board = Chessboard.parse("9x6", square_m=0.025)
>>> board.object_points().shape
(54, 3)
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera

Array = NDArray[np.float64]
Image = NDArray[np.uint8]

_BOARD_TEXT = re.compile(r"^\s*(\d+)\s*[xX×]\s*(\d+)\s*$")
# Sub-pixel refinement stops once a corner moves less than 1e-3 px.
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)


@dataclass(frozen=True)
class Chessboard:
    """A flat chessboard with ``cols`` × ``rows`` inner corners and squares of ``square_m`` metres."""

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3:
            raise ValueError(f"a board needs at least 3x3 inner corners, got {self.cols}x{self.rows}")
        if not (math.isfinite(self.square_m) and self.square_m > 0):
            raise ValueError(f"the square size must be a positive number of metres, got {self.square_m}")

    @classmethod
    def parse(cls, text: str, square_m: float) -> Chessboard:
        """``"9x6"`` (inner corners per row x per column) and the square size in metres."""
        match = _BOARD_TEXT.match(text)
        if not match:
            raise ValueError(f"a board is given as COLSxROWS inner corners, like 9x6, got {text!r}")
        return cls(int(match.group(1)), int(match.group(2)), float(square_m))

    @property
    def pattern_size(self) -> tuple[int, int]:
        return (self.cols, self.rows)

    def __len__(self) -> int:
        return self.cols * self.rows

    def object_points(self) -> Array:
        """The inner corners (N, 3) in the board's frame, row by row."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        return np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1).astype(np.float64) * self.square_m

    def find_corners(self, image: Image) -> Array | None:
        """The inner corners (N, 2) in pixels, sub-pixel refined, or None when the whole board is not
        found. ``image`` is grey or BGR."""
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
        found, corners = cv2.findChessboardCorners(grey, self.pattern_size, flags=flags)
        if found:
            window = self._subpix_window(np.asarray(corners, dtype=np.float64).reshape(-1, 2))
            refined = cv2.cornerSubPix(grey, corners.astype(np.float32), (window, window), (-1, -1), _SUBPIX_CRITERIA)
            return refined.reshape(-1, 2).astype(np.float64)
        # The sector-based detector copes better with the strong curvature near a fisheye's rim
        # and refines to sub-pixel by itself, but is some twenty times slower: only as a fallback.
        found, corners = cv2.findChessboardCornersSB(grey, self.pattern_size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
        return corners.reshape(-1, 2).astype(np.float64) if found else None

    def _subpix_window(self, corners: Array) -> int:
        grid = corners.reshape(self.rows, self.cols, 2)
        steps = np.concatenate(
            [np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel(), np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel()]
        )
        return int(np.clip(0.4 * steps.min(), 2, 11))


class BoardRenderer:
    """Draws a chessboard, held at any pose, through one camera model: every pixel's ray meets the
    board's plane, and the square it lands in sets the grey level. Only pixels near the board's
    outline in the image are traced.

    A one-square white margin surrounds the squares (detectors need it); the rest is mid grey.
    ``supersample`` rays per pixel side anti-alias the edges, as a real sensor integrates light."""

    def __init__(self, camera: Camera, board: Chessboard, supersample: int = 2) -> None:
        self.camera = camera
        self.board = board
        self.supersample = int(supersample)

    def render(
        self, R: Array, t: Array, noise_std: float = 0.0, rng: np.random.Generator | None = None
    ) -> Image:
        """A grey image of the board at pose (R, t): board point P maps to camera point R·P + t."""
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        t = np.asarray(t, dtype=np.float64).reshape(3)
        w, h = self.camera.image_size
        image = np.full((h, w), 128.0)
        box = self._image_box(R, t)
        if box is not None:
            u0, v0, u1, v1 = box
            image[v0:v1, u0:u1] = self._trace(R, t, u0, v0, u1, v1)
        if noise_std > 0:
            rng = rng if rng is not None else np.random.default_rng()
            image = image + rng.normal(0.0, noise_std, image.shape)
        image8: Image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        return image8

    def corners(self, R: Array, t: Array) -> Array:
        """Where the inner corners truly lie in the image (N, 2) for pose (R, t)."""
        points = self.board.object_points() @ np.asarray(R, dtype=np.float64).T + np.asarray(t, dtype=np.float64)
        return self.camera.project_directions(points)

    def _image_box(self, R: Array, t: Array) -> tuple[int, int, int, int] | None:
        """Pixel bounds (u0, v0, u1, v1) of the board with its margin, from a dense outline (edges
        curve in a fisheye image); None when none of it is in view."""
        b = self.board
        s = np.linspace(0.0, 1.0, 64)
        x0, x1, y0, y1 = -2.0, b.cols + 1.0, -2.0, b.rows + 1.0
        xs = np.concatenate([x0 + (x1 - x0) * s, np.full(64, x1), x1 - (x1 - x0) * s, np.full(64, x0)])
        ys = np.concatenate([np.full(64, y0), y0 + (y1 - y0) * s, np.full(64, y1), y1 - (y1 - y0) * s])
        outline = np.stack([xs, ys, np.zeros_like(xs)], axis=1) * b.square_m
        uv = self.camera.project_directions(outline @ R.T + t)
        uv = uv[np.isfinite(uv).all(axis=1)]
        if not len(uv):
            return None
        w, h = self.camera.image_size
        u0, v0 = np.clip(np.floor(uv.min(axis=0)) - 2, 0, [w, h]).astype(int)
        u1, v1 = np.clip(np.ceil(uv.max(axis=0)) + 3, 0, [w, h]).astype(int)
        return (int(u0), int(v0), int(u1), int(v1)) if u1 > u0 and v1 > v0 else None

    def _trace(self, R: Array, t: Array, u0: int, v0: int, u1: int, v1: int) -> Array:
        k = self.supersample
        offsets = (np.arange(k) + 0.5) / k - 0.5  # pixel (u, v) covers [u − ½, u + ½]
        us = (np.arange(u0, u1)[:, None] + offsets[None, :]).ravel()
        vs = (np.arange(v0, v1)[:, None] + offsets[None, :]).ravel()
        uu, vv = np.meshgrid(us, vs)
        d = self.camera.rays(np.stack([uu.ravel(), vv.ravel()], axis=1))
        normal = R[:, 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (normal @ t) / (d @ normal)
        hit = np.isfinite(s) & (s > 0)
        local = (np.where(hit, s, 0.0)[:, None] * np.nan_to_num(d) - t) @ R  # board frame
        u = local[:, 0] / self.board.square_m
        v = local[:, 1] / self.board.square_m
        b = self.board
        # Squares span [−1, cols] × [−1, rows] in square units; the margin one more square round.
        on_squares = hit & (u >= -1) & (u < b.cols) & (v >= -1) & (v < b.rows)
        on_margin = hit & (u >= -2) & (u < b.cols + 1) & (v >= -2) & (v < b.rows + 1)
        dark = (np.floor(u).astype(np.int64) + np.floor(v).astype(np.int64)) % 2 == 0
        grey = np.full(len(d), 128.0)
        grey[on_margin] = 235.0
        grey[on_squares & dark] = 20.0
        cells: Array = grey.reshape(v1 - v0, k, u1 - u0, k).mean(axis=(1, 3))
        return cells


def board_pose_facing(
    camera_direction: tuple[float, float, float], distance_m: float, board: Chessboard, tilt_deg: tuple[float, float] = (0.0, 0.0), spin_deg: float = 0.0
) -> tuple[Array, Array]:
    """A board pose (R, t) in camera coordinates whose centre lies ``distance_m`` along
    ``camera_direction`` and which faces the camera, then tilts by ``tilt_deg`` about its own
    x and y axes and spins by ``spin_deg`` about its normal. For making sets of calibration views."""
    direction = np.asarray(camera_direction, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    z = direction  # board normal points away from the camera
    helper = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    facing = np.stack([x, y, z], axis=1)
    tx, ty = (math.radians(a) for a in tilt_deg)
    spin = math.radians(spin_deg)
    R = facing @ _axis_rotation(0, tx) @ _axis_rotation(1, ty) @ _axis_rotation(2, spin)
    centre_local = np.array([(board.cols - 1) / 2.0, (board.rows - 1) / 2.0, 0.0]) * board.square_m
    t = direction * distance_m - R @ centre_local
    return R, t


def _axis_rotation(axis: int, angle: float) -> Array:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i] = m[j, j] = c
    m[i, j], m[j, i] = -s, s
    return m
