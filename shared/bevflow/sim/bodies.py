"""Human-shaped bodies made of ellipsoids, posed by a walking gait, standing or sitting.

A body is 14 ellipsoids (head, neck, torso, pelvis, upper arms, forearms, thighs, shins, feet).
They are exposed as data, ``BodyPrimitives`` (centres, principal axes, semi-axis lengths), so a
ray caster or an image renderer can use the exact shapes; ``surface_samples`` turns them into a
fixed number of surface points per body for splatting or visibility tests.

Everything is vectorised over N bodies. The body frame has x forward, y left and z up, with its
origin on the floor below the pelvis (the "feet" position the paper annotates); ``heading`` turns
it about Z. Proportions follow the usual anthropometric fractions of stature (Drillis & Contini).

>>> shape = BodyShape.standard(2)
>>> prims = pose_bodies(shape, feet_xy=np.array([[0.0, 0.0], [2.0, 1.0]]), heading=np.zeros(2),
...                     gait_phase=np.zeros(2), speed=np.zeros(2), posture=np.zeros(2, dtype=np.int64))
>>> prims.centers.shape, prims.axes.shape, prims.radii.shape
((2, 14, 3), (2, 14, 3, 3), (2, 14, 3))
>>> top = (prims.centers[:, 0, 2] + prims.radii[:, 0, 2]).round(3).tolist()  # head top = stature
>>> top
[1.72, 1.72]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from bevflow.detections import RowIndex

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class Posture(IntEnum):
    WALKING = 0
    STANDING = 1
    SITTING = 2


PART_NAMES: tuple[str, ...] = (
    "head", "neck", "torso", "pelvis",
    "upper_arm_left", "upper_arm_right", "forearm_left", "forearm_right",
    "thigh_left", "thigh_right", "shin_left", "shin_right", "foot_left", "foot_right",
)  # fmt: skip
PART_INDEX = {name: i for i, name in enumerate(PART_NAMES)}
# Below the knees: what a ceiling fisheye sees nearest its image centre, and what a counter hides.
LOWER_PARTS = tuple(PART_INDEX[n] for n in ("shin_left", "shin_right", "foot_left", "foot_right"))

# Joint heights and segment lengths as fractions of stature.
_ANKLE, _SHIN, _THIGH, _SHOULDER = 0.039, 0.246, 0.245, 0.818
_HIP = _ANKLE + _SHIN + _THIGH
_UPPER_ARM, _FOREARM_HAND = 0.186, 0.20
_REFERENCE_HEIGHT = 1.75
_MAX_THIGH_SWING = 0.42  # rad, at an ordinary 1.3 m/s walk
_SITTING_SEAT_DROP = _THIGH  # the thighs fold forward: the pelvis drops by their length


@dataclass(frozen=True, eq=False)
class BodyShape:
    """Per-body size: stature (m), shoulder (bideltoid) width (m) and a girth factor (1 = average)
    that scales torso depth and limb thickness."""

    height: FloatArray
    shoulder_width: FloatArray
    girth: FloatArray

    def __post_init__(self) -> None:
        h = np.asarray(self.height, dtype=np.float64).reshape(-1)
        object.__setattr__(self, "height", h)
        for name in ("shoulder_width", "girth"):
            value = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if len(value) != len(h):
                raise ValueError(f"{name} has {len(value)} rows, expected {len(h)}")
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.height)

    def __getitem__(self, index: RowIndex) -> BodyShape:
        return BodyShape(self.height[index], self.shoulder_width[index], self.girth[index])

    @classmethod
    def standard(cls, n: int, height: float = 1.72) -> BodyShape:
        return cls(np.full(n, height), np.full(n, 0.259 * height), np.ones(n))

    @classmethod
    def sample(cls, rng: np.random.Generator, n: int) -> BodyShape:
        """Adult statures 1.50–1.95 m; shoulders about 26 % of stature; girth ±15 %."""
        height = np.clip(rng.normal(1.72, 0.085, n), 1.5, 1.95)
        shoulder = height * np.clip(rng.normal(0.259, 0.012, n), 0.225, 0.29)
        girth = np.clip(rng.normal(1.0, 0.08, n), 0.85, 1.2)
        return cls(height, shoulder, girth)

    @staticmethod
    def concatenate(parts: list[BodyShape]) -> BodyShape:
        if not parts:
            return BodyShape(np.zeros(0), np.zeros(0), np.zeros(0))
        columns = ("height", "shoulder_width", "girth")
        return BodyShape(*(np.concatenate([getattr(p, f) for p in parts]) for f in columns))


@dataclass(frozen=True, eq=False)
class BodyPrimitives:
    """N bodies × P ellipsoids in world coordinates.

    ``centers`` (N, P, 3); ``axes`` (N, P, 3, 3) with ``axes[n, p, :, k]`` the unit world direction
    of semi-axis k; ``radii`` (N, P, 3) the semi-axis lengths. A point x is inside ellipsoid (n, p)
    when ‖(axesᵀ (x − c)) / radii‖ ≤ 1."""

    centers: FloatArray
    axes: FloatArray
    radii: FloatArray

    def __len__(self) -> int:
        return len(self.centers)

    @property
    def part_names(self) -> tuple[str, ...]:
        return PART_NAMES

    def contains(self, points: FloatArray) -> NDArray[np.bool_]:
        """(M, 3) world points → (M, N) whether each point lies inside any ellipsoid of body n."""
        rel = points[:, None, None, :] - self.centers[None]
        local = np.einsum("mnpi,npik->mnpk", rel, self.axes) / self.radii[None]
        inside: NDArray[np.bool_] = ((local**2).sum(-1) <= 1.0).any(-1)
        return inside

    def surface_samples(self, points_per_body: int = 256) -> SurfaceSamples:
        """A fixed, deterministic set of surface points per body (same layout for every body)."""
        part, unit = _unit_samples(points_per_body)
        c = self.centers[:, part]
        ax = self.axes[:, part]
        r = self.radii[:, part]
        ru, uq = r * unit, unit / r
        points = c + ax[..., 0] * ru[..., 0:1] + ax[..., 1] * ru[..., 1:2] + ax[..., 2] * ru[..., 2:3]
        # The normal of an ellipsoid at R·(r∘u) is R·(u / r), normalised.
        normals = ax[..., 0] * uq[..., 0:1] + ax[..., 1] * uq[..., 1:2] + ax[..., 2] * uq[..., 2:3]
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        return SurfaceSamples(points=points, normals=normals, part=part)


@dataclass(frozen=True, eq=False)
class SurfaceSamples:
    """``points`` and outward ``normals`` (N, K, 3) on the bodies' surfaces; ``part`` (K,) gives the
    primitive each of the K columns belongs to (the same for every body)."""

    points: FloatArray
    normals: FloatArray
    part: IntArray


def pose_bodies(
    shape: BodyShape,
    feet_xy: FloatArray,
    heading: FloatArray,
    gait_phase: FloatArray,
    speed: FloatArray,
    posture: IntArray,
) -> BodyPrimitives:
    """Place and pose N bodies. ``heading`` (rad) is the walking direction measured from +X,
    ``gait_phase`` (rad) the phase of the stride cycle, ``speed`` (m/s) sets the swing amplitude
    (standing still at speed 0), ``posture`` holds ``Posture`` values."""
    n = len(shape)
    h, g = shape.height, shape.girth
    s = h / _REFERENCE_HEIGHT
    feet_xy = np.asarray(feet_xy, dtype=np.float64).reshape(n, 2)
    posture = np.asarray(posture).reshape(n)
    sitting = posture == Posture.SITTING
    walking = posture == Posture.WALKING
    amp = np.where(walking, _MAX_THIGH_SWING * np.clip(np.asarray(speed) / 1.3, 0.0, 1.25), 0.0)
    phase = np.asarray(gait_phase, dtype=np.float64).reshape(n)

    # Leg angles (pitch from vertical, positive = forward). Knees flex while the leg swings forward.
    side = np.array([1.0, -1.0])  # left, right
    thigh = amp[:, None] * np.sin(phase)[:, None] * side
    knee = amp[:, None] * (0.15 + 1.2 * np.maximum(0.0, np.cos(phase)[:, None] * side))
    thigh = np.where(sitting[:, None], math.pi / 2, thigh)
    knee = np.where(sitting[:, None], math.pi / 2, knee)
    shin = thigh - knee

    thigh_len, shin_len = (_THIGH * h)[:, None], (_SHIN * h)[:, None]
    leg_drop = (thigh_len + shin_len) - (thigh_len * np.cos(thigh) + shin_len * np.cos(shin)).max(axis=1, keepdims=True)
    drop = np.where(sitting, _SITTING_SEAT_DROP * h, leg_drop[:, 0])  # pelvis lowering
    hip_z = _HIP * h - drop
    hip_y = 0.055 * h
    hips = np.stack([np.zeros((n, 2)), hip_y[:, None] * side, np.repeat(hip_z[:, None], 2, 1)], -1)
    knees = hips + thigh_len[..., None] * _pitch_dir(thigh)
    ankles = knees + shin_len[..., None] * _pitch_dir(shin)

    # Arms swing against the legs; elbows bend a little more the faster the walk.
    arm = np.where(sitting[:, None], 0.25, -0.8 * thigh)
    elbow = np.where(sitting[:, None], 1.1, 0.2 + 0.5 * amp[:, None])
    shoulder_z = _SHOULDER * h - drop
    shoulder_y = shape.shoulder_width / 2 - 0.05 * s
    shoulders = np.stack([np.zeros((n, 2)), shoulder_y[:, None] * side, np.repeat(shoulder_z[:, None], 2, 1)], -1)
    abduct = np.array([0.08, -0.08])
    elbows = shoulders + (_UPPER_ARM * h)[:, None, None] * _pitch_dir(arm, abduct)
    wrists = elbows + (_FOREARM_HAND * h)[:, None, None] * _pitch_dir(arm + elbow, abduct)

    top = h - drop
    head_r = np.stack([0.095 * s, 0.08 * s, 0.115 * s], -1)
    neck_base = np.stack([np.zeros(n), np.zeros(n), shoulder_z - 0.02 * s], -1)
    chin = np.stack([0.01 * s, np.zeros(n), top - 2 * head_r[:, 2] + 0.03 * s], -1)
    torso_bottom = hip_z + 0.07 * h
    torso_c = np.stack([np.zeros(n), np.zeros(n), (shoulder_z + torso_bottom) / 2 + 0.01 * s], -1)
    torso_half_height = (shoulder_z - torso_bottom) / 2 + 0.05 * s
    torso_r = np.stack([0.115 * s * g, shape.shoulder_width / 2 - 0.075 * s * g, torso_half_height], -1)
    pelvis_c = np.stack([np.zeros(n), np.zeros(n), hip_z + 0.03 * h], -1)
    pelvis_r = np.stack([0.10 * s * g, 0.165 * s * g, 0.09 * s], -1)
    foot_c = ankles + np.stack([0.055 * s, 0 * s, 0 * s], -1)[:, None, :]
    foot_c[..., 2] = 0.035 * s[:, None]
    foot_r = np.stack([0.125 * s, 0.045 * s, 0.035 * s], -1)

    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    centers = np.empty((n, len(PART_NAMES), 3))
    axes = np.empty((n, len(PART_NAMES), 3, 3))
    radii = np.empty((n, len(PART_NAMES), 3))
    centers[:, 0] = np.stack([np.zeros(n), np.zeros(n), top - head_r[:, 2]], -1)
    axes[:, 0], radii[:, 0] = eye, head_r
    for p, c, r in ((2, torso_c, torso_r), (3, pelvis_c, pelvis_r)):
        centers[:, p], axes[:, p], radii[:, p] = c, eye, r
    _segment(centers, axes, radii, 1, neck_base, chin, 0.055 * s * g)
    for k in range(2):
        _segment(centers, axes, radii, 4 + k, shoulders[:, k], elbows[:, k], 0.047 * s * g)
        _segment(centers, axes, radii, 6 + k, elbows[:, k], wrists[:, k], 0.038 * s * g)
        _segment(centers, axes, radii, 8 + k, hips[:, k], knees[:, k], 0.075 * s * g)
        _segment(centers, axes, radii, 10 + k, knees[:, k], ankles[:, k], 0.052 * s * g)
        centers[:, 12 + k], axes[:, 12 + k], radii[:, 12 + k] = foot_c[:, k], eye, foot_r
    return _to_world(centers, axes, radii, feet_xy, np.asarray(heading, dtype=np.float64).reshape(n))


def _pitch_dir(pitch: FloatArray, abduct: FloatArray | float = 0.0) -> FloatArray:
    """Unit direction of a limb hanging down, pitched forward by ``pitch`` and out sideways."""
    ca = np.cos(abduct)
    return np.stack([np.sin(pitch) * ca, np.broadcast_to(np.sin(abduct), pitch.shape), -np.cos(pitch) * ca], -1)


def _segment(
    centers: FloatArray, axes: FloatArray, radii: FloatArray, p: int, a: FloatArray, b: FloatArray, r: FloatArray
) -> None:
    """An ellipsoid spanning joints a→b (N, 3) with cross radius r; it overlaps the joints a bit
    so neighbouring segments leave no gap at bent knees and elbows."""
    d = b - a
    length = np.linalg.norm(d, axis=-1)
    u = d / length[:, None]
    # Second axis: the body's left (+Y) made perpendicular to u; limbs never point along Y.
    v = np.array([0.0, 1.0, 0.0]) - u * u[:, 1:2]
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    w = np.cross(u, v)
    centers[:, p] = (a + b) / 2
    axes[:, p] = np.stack([u, v, w], -1)
    radii[:, p] = np.stack([length / 2 + 0.5 * r, r, r], -1)


def _to_world(
    centers: FloatArray, axes: FloatArray, radii: FloatArray, feet_xy: FloatArray, heading: FloatArray
) -> BodyPrimitives:
    c, s = np.cos(heading), np.sin(heading)
    zero, one = np.zeros_like(c), np.ones_like(c)
    rot = np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, one], -1)], -2)
    world_c = np.einsum("nij,npj->npi", rot, centers)
    world_c[..., :2] += feet_xy[:, None, :]
    world_axes = np.einsum("nij,npjk->npik", rot, axes)
    return BodyPrimitives(centers=world_c, axes=world_axes, radii=radii)


@lru_cache(maxsize=8)
def _unit_samples(points_per_body: int) -> tuple[IntArray, FloatArray]:
    """Per-column part index and unit-sphere direction, split over parts by surface area of a
    reference standing body, so points are about evenly spread over the skin."""
    if points_per_body < 4 * len(PART_NAMES):
        raise ValueError(f"points_per_body must be at least {4 * len(PART_NAMES)}, got {points_per_body}")
    zero = np.zeros(1)
    ref = pose_bodies(BodyShape.standard(1), np.zeros((1, 2)), zero, zero, zero, np.full(1, int(Posture.STANDING)))
    a, b, c = ref.radii[0].T
    p = 1.6075  # Knud Thomsen's approximation of an ellipsoid's area
    area = 4 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3) ** (1 / p)
    spare = points_per_body - 4 * len(PART_NAMES)
    share = spare * area / area.sum()
    counts = 4 + np.floor(share).astype(np.int64)
    counts[np.argsort(-(share - np.floor(share)), kind="stable")[: points_per_body - counts.sum()]] += 1
    part = np.repeat(np.arange(len(PART_NAMES)), counts)
    unit = np.concatenate([_fibonacci_sphere(int(k)) for k in counts])
    part.setflags(write=False)
    unit.setflags(write=False)
    return part, unit


def _fibonacci_sphere(n: int) -> FloatArray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    rho = np.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], -1)
