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
from functools import cached_property
from typing import Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

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
    rotation: Array = cam_to_world.T
    return rotation


def rotation_from_vector(rvec: ArrayLike) -> Array:
    """The rotation matrix (3, 3) of a Rodrigues rotation vector (OpenCV's ``rvec``)."""
    return np.asarray(cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0], dtype=np.float64)


def rotation_vector(R: ArrayLike) -> Array:
    """The Rodrigues rotation vector (3,) of a rotation matrix: ``rotation_from_vector`` undone."""
    return np.asarray(cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0], dtype=np.float64).ravel()


def tilt_deg(R: ArrayLike) -> float:
    """Angle between the optical axis of a camera with world-to-camera rotation ``R`` and straight
    down, degrees (0: looking straight down, 90: level). The axis in the world is Rᵀ (0, 0, 1)."""
    axis_in_world = np.asarray(R, dtype=np.float64).T @ np.array([0.0, 0.0, 1.0])
    return math.degrees(math.acos(float(np.clip(-axis_in_world[2], -1.0, 1.0))))


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
        return rotation_vector(self.R)

    @property
    def tilt_deg(self) -> float:
        """Angle between the optical axis and straight down (``tilt_deg``)."""
        return tilt_deg(self.R)

    def world_to_camera(self, points: Array) -> Array:
        return np.asarray(points, dtype=np.float64) @ self.R.T + self.t

    def nadir_pixel(self) -> Array:
        """Where the vertical through the camera meets the image: the image of the point straight
        below it (for a ceiling camera), or the vanishing point of vertical lines in general.
        For a downward fisheye this is close to the image centre; for a side-view camera it lies far
        below the image, so "the box point nearest the nadir" becomes the box's bottom centre."""
        down_in_camera = self.R @ np.array([0.0, 0.0, -1.0])
        pixel: Array = self.project_directions(down_in_camera[None, :])[0]
        return pixel

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
        # Pixel centres sit at integer coordinates, so a resize maps u to (u + 0.5)·factor − 0.5
        # (as cv2.resize does); scaling cx, cy alone would shift the image by half a pixel.
        K[:2, 2] += 0.5 * factor - 0.5
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

    @cached_property
    def max_theta(self) -> float:
        """The largest angle off the optical axis (radians, at most π) up to which θd(θ) keeps
        growing. Beyond it the polynomial folds back: far points would land on the image again,
        and no pixel could be traced back to them, so ``project`` and ``rays`` stop there."""
        k1, k2, k3, k4 = self.dist
        # dθd/dθ = 1 + 3k1 s + 5k2 s² + 7k3 s³ + 9k4 s⁴ with s = θ²; its first positive root ends the lens.
        return math.sqrt(_first_positive_root([1.0, 3 * k1, 5 * k2, 7 * k3, 9 * k4], limit=math.pi**2))

    def distort_theta(self, theta: Array) -> Array:
        k1, k2, k3, k4 = self.dist
        t2 = theta * theta
        distorted: Array = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        return distorted

    def undistort_theta(self, theta_d: Array, iterations: int = 20) -> Array:
        """Invert θd = θ(1 + k1θ² + …) on [0, max_theta] by Newton's method, vectorised (OpenCV
        iterates too). NaN where θd is beyond what the lens reaches or Newton did not converge."""
        k1, k2, k3, k4 = self.dist
        theta_d = np.asarray(theta_d, dtype=np.float64)
        top = self.max_theta
        theta = np.clip(theta_d, 0.0, top)
        if not self.dist.any():  # equidistant lens: θd = θ
            return np.where(theta_d <= top, theta, np.nan)
        for _ in range(iterations):
            t2 = theta * theta
            f = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            if np.all(~(np.abs(f) > 1e-14)):  # converged everywhere (NaN rows never will)
                break
            df = 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            theta = np.clip(theta - f / np.where(np.abs(df) < 1e-12, 1e-12, df), 0.0, top)
        converged = np.abs(self.distort_theta(theta) - theta_d) <= 1e-9 * np.maximum(1.0, np.abs(theta_d))
        return np.where(converged, theta, np.nan)

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
        # Unseen: anything past the fold of the lens polynomial, the zero vector, and the direction
        # straight behind the camera (every azimuth at once, so no single pixel).
        unseen = (theta > self.max_theta) | ((rxy <= 1e-12) & (xc[:, 2] <= 1e-12))
        out[unseen] = np.nan
        return out

    def rays(self, pixels: Array) -> Array:
        """Pixels (N, 2) to unit ray directions (N, 3) in the camera frame; NaN for pixels beyond
        the lens's reach (outside the image circle of a distortion polynomial that folds back)."""
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        K = self.K
        y = (p[:, 1] - K[1, 2]) / K[1, 1]
        x = (p[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        theta_d = np.hypot(x, y)
        theta = self.undistort_theta(theta_d)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(theta_d <= 1e-12, 1.0, np.sin(theta) / theta_d)  # NaN pixels stay NaN
        return np.stack([x * s, y * s, np.cos(theta)], axis=1)


def _first_positive_root(coefficients: list[float], limit: float) -> float:
    """The smallest real root in (0, limit] of the polynomial c0 + c1 s + c2 s² + …, else ``limit``."""
    roots = np.polynomial.polynomial.polyroots(np.trim_zeros(np.asarray(coefficients, dtype=np.float64), "b"))
    real = roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots.real))].real
    real = real[(real > 0) & (real <= limit)]
    return float(real.min()) if len(real) else limit


@dataclass(frozen=True, eq=False)
class PinholeCamera(Camera):
    kind: CameraKind = field(init=False, default="pinhole")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.dist.size not in (0, 4, 5, 8):
            raise ValueError(f"pinhole distortion needs 0, 4, 5 or 8 coefficients, got {self.dist.size}")

    @cached_property
    def max_radius(self) -> float:
        """The largest normalised radius r = |(X/Z, Y/Z)| up to which the radial distortion keeps
        pushing points outward (∞ if it always does). Past it a calibrated polynomial folds back,
        so points far outside the field of view would land inside the image; ``project`` and
        ``rays`` stop there. (The small tangential terms are left out of this limit.)"""
        d = np.zeros(8)
        d[: self.dist.size] = self.dist
        k1, k2, _, _, k3, k4, k5, k6 = d
        P = np.polynomial.Polynomial
        num, den = P([1.0, k1, k2, k3]), P([1.0, k4, k5, k6])  # radial factor num(s)/den(s), s = r²
        s = P([0.0, 1.0])
        # d/dr [r·num/den] = [(num + 2s·num')·den − 2s·num·den'] / den²;
        # its first zero, or a pole of den, ends the field.
        slope = (num + 2 * s * num.deriv()) * den - 2 * s * num * den.deriv()
        limit = 1e12
        end = min(_first_positive_root(list(slope.coef), limit), _first_positive_root(list(den.coef), limit))
        return math.sqrt(end) if end < limit else math.inf

    def project_directions(self, xc: Array) -> Array:
        xc = np.asarray(xc, dtype=np.float64).reshape(-1, 3)
        out = np.full((len(xc), 2), np.nan)
        front = xc[:, 2] > 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            front &= np.hypot(xc[:, 0], xc[:, 1]) <= self.max_radius * xc[:, 2]
        if front.any():
            pts, _ = cv2.projectPoints(xc[front], np.zeros(3), np.zeros(3), self.K, self.dist)
            out[front] = pts.reshape(-1, 2)
        return out

    def rays(self, pixels: Array) -> Array:
        """Pixels (N, 2) to unit ray directions (N, 3) in the camera frame; NaN for pixels no
        point in the valid field projects to."""
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if len(p) == 0:
            return np.zeros((0, 3))
        # OpenCV's default stops after 5 fixed-point steps, which leaves pixels of error with real
        # distortion; iterate to convergence instead.
        ab = cv2.undistortPoints(p, self.K, self.dist, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
        d = np.concatenate([ab, np.ones((len(ab), 1))], axis=1)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if self.dist.any():
            # The iteration has no solution past the fold of the polynomial: check it by reprojecting.
            back = self.project_directions(d)
            d[~(np.linalg.norm(back - p.reshape(-1, 2), axis=1) <= 1e-4)] = np.nan
        return d

    def nadir_pixel(self) -> Array:
        """As ``Camera.nadir_pixel``, but always finite: a tilted or level pinhole camera gets a
        point below its image (its undistorted vanishing point of verticals, or a far point)."""
        down = self.R @ np.array([0.0, 0.0, -1.0])
        pixel: Array = self.project_directions(down[None, :])[0]
        if np.isfinite(pixel).all():
            return pixel
        K = self.K
        if down[2] > 1e-9:
            # The vanishing point lies outside the calibrated field, where the distortion polynomial
            # means nothing; the undistorted projection is what "below the image" needs.
            pixel = (K @ (down / down[2]))[:2]
            return pixel
        # Level or upward-looking camera: verticals meet at infinity, so return a point far along
        # the image direction of "down".
        direction = K[:2, :2] @ down[:2]
        pixel = K[:2, 2] + 1e7 * direction / max(float(np.linalg.norm(direction)), 1e-12)
        return pixel


_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)


def make_camera(kind: CameraKind, K: Array, dist: Array, R: Array, t: Array, image_size: tuple[int, int]) -> Camera:
    cls = FisheyeCamera if kind == "fisheye" else PinholeCamera
    return cls(K=K, dist=dist, R=R, t=t, image_size=image_size)
