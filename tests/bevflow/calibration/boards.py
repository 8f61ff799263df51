"""Synthetic chessboard views for the calibration tests: known lens, known board poses."""

from __future__ import annotations

import math

import numpy as np

from bevflow.calibration.chessboard import BoardRenderer, Chessboard, board_pose_facing
from bevflow.calibration.intrinsics import BoardView
from bevflow.camera import Camera, FisheyeCamera, PinholeCamera

BOARD = Chessboard(9, 6, 0.03)
# A 185° lens on a 640 px sensor, principal point off centre, fx ≠ fy, all four k's in use.
FISHEYE = FisheyeCamera(
    K=np.array([[205.0, 0.0, 322.3], [0.0, 204.0, 318.1], [0.0, 0.0, 1.0]]),
    dist=np.array([0.03, -0.01, 0.002, -0.0003]),
    R=np.eye(3),
    t=np.zeros(3),
    image_size=(640, 640),
)
PINHOLE = PinholeCamera(
    K=np.array([[520.0, 0.0, 318.0], [0.0, 522.0, 243.0], [0.0, 0.0, 1.0]]),
    dist=np.array([-0.28, 0.09, 0.0008, -0.0005, -0.012]),
    R=np.eye(3),
    t=np.zeros(3),
    image_size=(640, 480),
)


def board_poses(camera: Camera, n: int, seed: int, max_angle_deg: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` board poses spread over the field of view (every other one near the rim), tilted
    and spun at random, each with the whole board inside the image. ``max_angle_deg`` (how far
    off axis the board's centre goes) defaults to 72° for a fisheye and 22° for a pinhole."""
    if max_angle_deg is None:
        max_angle_deg = 72.0 if camera.kind == "fisheye" else 22.0
    rng = np.random.default_rng(seed)
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(200 * n):
        if len(poses) == n:
            break
        rim = len(poses) % 2 == 0
        theta = math.radians(rng.uniform(0.6 * max_angle_deg, max_angle_deg) if rim else rng.uniform(0.0, max_angle_deg))
        phi = rng.uniform(0.0, 2 * math.pi)
        direction = (math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta))
        distance = rng.uniform(0.35, 0.55) if camera.kind == "fisheye" else rng.uniform(0.45, 0.8)
        R, t = board_pose_facing(direction, distance, BOARD, (rng.uniform(-35, 35), rng.uniform(-35, 35)), rng.uniform(-40, 40))
        corners = camera.project_directions(BOARD.object_points() @ R.T + t)
        if camera.in_image(corners, margin=-12).all():
            poses.append((R, t))
    assert len(poses) == n, "no room for the board in this camera's view"
    return poses


def projected_views(camera: Camera, n: int, noise_px: float, seed: int) -> list[BoardView]:
    """The true corners of ``n`` poses with Gaussian pixel noise, as a detector would give them."""
    rng = np.random.default_rng(seed + 1000)
    renderer = BoardRenderer(camera, BOARD)
    return [
        BoardView(f"view{k:02d}", renderer.corners(R, t) + rng.normal(0.0, noise_px, (len(BOARD), 2)))
        for k, (R, t) in enumerate(board_poses(camera, n, seed))
    ]


def rendered_images(camera: Camera, n: int, seed: int, noise_grey: float = 2.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` grey images of the board and, for each, its true corners (N, 2)."""
    rng = np.random.default_rng(seed + 2000)
    renderer = BoardRenderer(camera, BOARD)
    return [(renderer.render(R, t, noise_grey, rng), renderer.corners(R, t)) for R, t in board_poses(camera, n, seed)]


def projection_gap_px(estimate: Camera, truth: Camera, max_angle_deg: float) -> float:
    """The largest distance between where the two lenses image the same direction, over directions
    up to ``max_angle_deg`` off the optical axis."""
    theta = np.radians(np.linspace(0.0, max_angle_deg, 60))
    phi = np.radians(np.arange(0.0, 360.0, 10.0))
    T, P = np.meshgrid(theta, phi)
    directions = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1).reshape(-1, 3)
    return float(np.nanmax(np.linalg.norm(estimate.project_directions(directions) - truth.project_directions(directions), axis=1)))
