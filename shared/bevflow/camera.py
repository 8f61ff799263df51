"""Camera models: world points to pixels and pixels back to world rays.

Two models share one interface:

- ``FisheyeCamera``: OpenCV's fisheye (equidistant + polynomial) model, the paper's section 3.3.
  θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸). θ is computed with ``atan2`` so points beyond 90° off the
  optical axis (a 190° lens) still project; for points in front of the camera it equals OpenCV's
  ``atan(r)``.
- ``PinholeCamera``: OpenCV's pinhole model with (k1, k2, p1, p2, k3) distortion, so calibrated
  datasets such as WILDTRACK load as they are.

Conventions: world frame X, Y on the floor, Z up, metres. Extrinsics map world to camera
(``Xc = R X + t``), as in OpenCV. Every method takes arrays of N points and is float64.

>>> cam = FisheyeCamera.looking_down(position=(0.0, 0.0, 3.3), image_size=(1024, 1024), fov_deg=180)
>>> uv = cam.project(np.array([[1.0, 0.5, 0.0]]))
>>> np.allclose(cam.pixels_to_plane(uv, z=0.0), [[1.0, 0.5, 0.0]])
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
CameraKind = Literal["fisheye", "pinhole"]


def rotation_from_ypr(yaw_deg: float, pitch_deg: float, roll_deg: float) -> Array:
    """World-to-camera rotation for a camera that starts looking straight down (optical axis −Z,
    image x along world +X, image y along world −Y), then turns by yaw about world Z, tilts by
    pitch about its own x axis, and rolls about its optical axis. Angles in degrees.

    Ceiling cameras are described this way on site plans: yaw is the heading of the image's
    right-hand edge, pitch the tilt away from vertical.
    """
    down = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # camera axes in world
    yaw, pitch, roll = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    rz = _rot_z(yaw)
    rx = _rot_x(pitch)
    rr = _rot_z(roll)
    cam_to_world = rz @ down @ rx @ rr
    return cam_to_world.T


def _rot_z(a: float) -> Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_x(a: float) -> Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


@dataclass(frozen=True, eq=False)
class Camera:
    """Intrinsics K (3×3), distortion, world-to-camera R (3×3), t (3,), image size (w, h)."""

    K: Array
    dist: Array
    R: Array
    t: Array
    image_size: tuple[int, int]
    kind: CameraKind = field(init=False, default="pinhole")

    def __post_init__(self) -> None:
        for name, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            value = np.asarray(getattr(self, name), dtype=np.float64).reshape(shape)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        dist = np.asarray(self.dist, dtype=np.float64).ravel()
        dist.setflags(write=False)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "image_size", (int(self.image_size[0]), int(self.image_size[1])))

    # --- pose -----------------------------------------------------------------------------------
    @property
    def center(self) -> Array:
        """The optical centre in world coordinates."""
        return -self.R.T @ self.t

    @property
    def rvec(self) -> Array:
        return cv2.Rodrigues(self.R)[0].ravel()

    def world_to_camera(self, points: Array) -> Array:
        return np.asarray(points, dtype=np.float64) @ self.R.T + self.t

    def nadir_pixel(self) -> Array:
        """Where the vertical through the camera meets the image: the image of the point straight
        below it (for a ceiling camera), or the vanishing point of vertical lines in general.
        For a downward fisheye this is close to the image centre; for a side-view camera it lies far
        below the image, so "the box point nearest the nadir" becomes the box's bottom centre."""
        down_in_camera = self.R @ np.array([0.0, 0.0, -1.0])
        return self.project_directions(down_in_camera[None, :])[0]

    # --- projection -----------------------------------------------------------------------------
    def project(self, points: Array) -> Array:
        """World points (N, 3) to pixels (N, 2). Points the model cannot see give NaN."""
        return self.project_directions(self.world_to_camera(points))

    def project_directions(self, xc: Array) -> Array:
        raise NotImplementedError

    def rays(self, pixels: Array) -> Array:
        """Pixels (N, 2) to unit ray directions (N, 3) in the camera frame."""
        raise NotImplementedError

    def world_rays(self, pixels: Array) -> Array:
        """Pixels (N, 2) to unit ray directions (N, 3) in the world frame, starting at ``center``."""
        return self.rays(pixels) @ self.R

    def pixels_to_plane(self, pixels: Array, z: float | Array = 0.0) -> Array:
        """Intersect the rays through ``pixels`` with the horizontal plane(s) Z = z.

        Returns world points (N, 3); NaN where the ray never reaches the plane (parallel, or the
        plane lies behind the camera)."""
        d = self.world_rays(np.asarray(pixels, dtype=np.float64).reshape(-1, 2))
        c = self.center
        z = np.broadcast_to(np.asarray(z, dtype=np.float64), (len(d),))
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - c[2]) / d[:, 2]
        s = np.where(np.isfinite(s) & (s > 0), s, np.nan)
        return c + s[:, None] * d

    def in_image(self, pixels: Array, margin: float = 0.0) -> NDArray[np.bool_]:
        w, h = self.image_size
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        return (
            np.isfinite(p).all(axis=1)
            & (p[:, 0] >= -margin)
            & (p[:, 0] <= w - 1 + margin)
            & (p[:, 1] >= -margin)
            & (p[:, 1] <= h - 1 + margin)
        )

    def with_pose(self, R: Array, t: Array) -> Camera:
        return type(self)(K=self.K, dist=self.dist, R=R, t=t, image_size=self.image_size)

    def scaled(self, factor: float) -> Camera:
        """The same camera with its image resized by ``factor`` (as the detector's input is)."""
        K = self.K.copy()
        K[:2, :] *= factor
        w, h = self.image_size
        size = (int(round(w * factor)), int(round(h * factor)))
        return type(self)(K=K, dist=self.dist, R=self.R, t=self.t, image_size=size)


@dataclass(frozen=True, eq=False)
class FisheyeCamera(Camera):
    kind: CameraKind = field(init=False, default="fisheye")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.dist.shape != (4,):
            raise ValueError(f"fisheye distortion needs 4 coefficients k1..k4, got {self.dist.size}")

    @classmethod
    def looking_down(
        cls,
        position: tuple[float, float, float],
        image_size: tuple[int, int],
        fov_deg: float = 185.0,
        yaw_deg: float = 0.0,
        dist: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
    ) -> FisheyeCamera:
        """An equidistant ceiling fisheye whose image circle fills the shorter image side."""
        w, h = image_size
        f = (min(w, h) / 2.0) / math.radians(fov_deg / 2.0)
        K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        R = rotation_from_ypr(yaw_deg, 0.0, 0.0)
        t = -R @ np.asarray(position, dtype=np.float64)
        return cls(K=K, dist=np.asarray(dist), R=R, t=t, image_size=image_size)

    def distort_theta(self, theta: Array) -> Array:
        k1, k2, k3, k4 = self.dist
        t2 = theta * theta
        return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))

    def undistort_theta(self, theta_d: Array, iterations: int = 12) -> Array:
        """Invert θd = θ(1 + k1θ² + …) by Newton's method, vectorised (OpenCV iterates too)."""
        k1, k2, k3, k4 = self.dist
        theta = np.array(theta_d, dtype=np.float64, copy=True)
        for _ in range(iterations):
            t2 = theta * theta
            f = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            df = 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            theta -= f / np.where(np.abs(df) < 1e-12, 1e-12, df)
        return theta

    def project_directions(self, xc: Array) -> Array:
        xc = np.asarray(xc, dtype=np.float64).reshape(-1, 3)
        rxy = np.hypot(xc[:, 0], xc[:, 1])
        theta = np.arctan2(rxy, xc[:, 2])
        theta_d = self.distort_theta(theta)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(rxy > 1e-12, theta_d / rxy, 1.0 / np.maximum(xc[:, 2], 1e-12))
        x = xc[:, 0] * scale
        y = xc[:, 1] * scale
        K = self.K
        u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
        v = K[1, 1] * y + K[1, 2]
        out = np.stack([u, v], axis=1)
        out[np.linalg.norm(xc, axis=1) < 1e-12] = np.nan
        return out

    def rays(self, pixels: Array) -> Array:
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        K = self.K
        y = (p[:, 1] - K[1, 2]) / K[1, 1]
        x = (p[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        theta_d = np.hypot(x, y)
        theta = self.undistort_theta(theta_d)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(theta_d > 1e-12, np.sin(theta) / theta_d, 1.0)
        return np.stack([x * s, y * s, np.cos(theta)], axis=1)


@dataclass(frozen=True, eq=False)
class PinholeCamera(Camera):
    kind: CameraKind = field(init=False, default="pinhole")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.dist.size not in (0, 4, 5, 8):
            raise ValueError(f"pinhole distortion needs 0, 4, 5 or 8 coefficients, got {self.dist.size}")

    def project_directions(self, xc: Array) -> Array:
        xc = np.asarray(xc, dtype=np.float64).reshape(-1, 3)
        out = np.full((len(xc), 2), np.nan)
        front = xc[:, 2] > 1e-9
        if front.any():
            pts, _ = cv2.projectPoints(xc[front], np.zeros(3), np.zeros(3), self.K, self.dist)
            out[front] = pts.reshape(-1, 2)
        return out

    def rays(self, pixels: Array) -> Array:
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if len(p) == 0:
            return np.zeros((0, 3))
        ab = cv2.undistortPoints(p, self.K, self.dist).reshape(-1, 2)
        d = np.concatenate([ab, np.ones((len(ab), 1))], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def make_camera(
    kind: CameraKind, K: Array, dist: Array, R: Array, t: Array, image_size: tuple[int, int]
) -> Camera:
    cls = FisheyeCamera if kind == "fisheye" else PinholeCamera
    return cls(K=K, dist=dist, R=R, t=t, image_size=image_size)
