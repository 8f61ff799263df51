"""What each camera sees of a scene: the boxes a perfect detector would give.

For one frame and one camera, every body's surface samples are tested for visibility:

- self: a point faces away from the camera when its surface normal does (the far side of a body);
- other people: the ray from the camera centre to the point crosses another body's ellipsoids;
- static objects: the ray crosses a pillar (finite vertical cylinder) or a shelf (box).

The rays are tested exactly against the primitives, not through a rasterised depth buffer, so
visibility does not depend on an image resolution and has no holes, whatever the distance.
To stay fast it only tests pairs that can interact: points inside another body's image box, and
bodies with an obstacle near their line of sight on the floor plan. A person's box is the bounding
box of the pixels of their visible points; people who are barely visible, outside the camera's
monitored radius or outside its image are not in the view.

Self-occlusion between a body's own parts (an arm in front of the torso) is not tested: it never
changes the silhouette, so it changes neither the box nor what other bodies hide.

>>> from bevflow.camera import FisheyeCamera
>>> from bevflow.sim.scene import Scene, SceneConfig
>>> cam = FisheyeCamera.looking_down((4.0, 3.0, 3.3), (1280, 1280))
>>> rig = CameraRig([cam], monitored_radius_m=[3.5])
>>> frame = next(iter(Scene(SceneConfig(floor=(0.0, 0.0, 8.0, 6.0), identities=3, seed=2))))
>>> (view,) = rig.observe(frame)
>>> len(view.boxes) == len(view.person_ids) <= 3
True
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Protocol, TypedDict, Unpack

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera
from bevflow.detections import Boxes
from bevflow.sim.bodies import LOWER_PARTS, BodyPrimitives
from bevflow.sim.scene import Obstacles, Scene, SceneFrame
from bevflow.site import Site

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

_BODY_REACH_M = 0.8  # the farthest any body point lies from its feet position on the floor plan
# From a ceiling camera a ray only moves outward as it descends, so whatever hides a point lies
# nearer the camera's axis than the point: bodies beyond the monitored radius + two reaches can
# hide nobody inside it.
_OCCLUDER_MARGIN_M = 2 * _BODY_REACH_M


@dataclass(frozen=True, eq=False)
class CameraView:
    """The people one camera sees in one frame, row-aligned: their ``boxes`` (bounding boxes of
    the visible silhouette, pixels), ``person_ids``, the ``visible_fraction`` of their camera-facing
    surface, whether the feet side is hidden (``lower_occluded``: under half of the surface below
    the knees is visible), and their ground-truth ``feet_xy`` on the floor.

    ``in_sight_ids`` (not row-aligned) lists everyone inside the monitored radius with any part of
    the body in view, boxed or not: a superset of ``person_ids`` that also holds people too hidden
    to be boxed. It is who an annotator of this camera's video would mark (default: ``person_ids``)."""

    camera_index: int
    boxes: Boxes
    person_ids: IntArray
    visible_fraction: FloatArray
    lower_occluded: BoolArray
    feet_xy: FloatArray
    in_sight_ids: IntArray | None = None

    def __post_init__(self) -> None:
        if self.in_sight_ids is None:
            object.__setattr__(self, "in_sight_ids", self.person_ids)

    def __len__(self) -> int:
        return len(self.person_ids)

    @classmethod
    def empty(cls, camera_index: int) -> CameraView:
        return cls(camera_index, Boxes.empty(), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool), np.zeros((0, 2)))


class RigOptions(TypedDict, total=False):
    """``CameraRig``'s settings after its cameras, radii and obstacles."""

    points_per_body: int
    min_visible_fraction: float
    min_box_px: float


class PeopleOnFloor(Protocol):
    """What ``GroundTruthTracks`` reads of a frame: who is there and where their feet are."""

    @property
    def person_ids(self) -> NDArray[np.int64]: ...
    @property
    def feet_xy(self) -> NDArray[np.float64]: ...


class CameraRig:
    """The cameras of a site, the static obstacles they look past, and the visibility rules.

    ``monitored_radius_m`` per camera limits who counts as seen (feet within that floor distance of
    the point below the camera; None: anywhere in the image). ``min_visible_fraction`` drops people
    who are mostly hidden; ``min_box_px`` drops slivers."""

    def __init__(
        self,
        cameras: Sequence[Camera],
        monitored_radius_m: Sequence[float | None] | None = None,
        obstacles: Obstacles | None = None,
        points_per_body: int = 256,
        min_visible_fraction: float = 0.25,
        min_box_px: float = 3.0,
    ) -> None:
        self.cameras = list(cameras)
        radii = list(monitored_radius_m) if monitored_radius_m is not None else [None] * len(self.cameras)
        if len(radii) != len(self.cameras):
            raise ValueError(f"{len(radii)} monitored radii for {len(self.cameras)} cameras")
        self.monitored_radius_m = radii
        self.obstacles = obstacles if obstacles is not None else Obstacles()
        self.points_per_body = points_per_body
        self.min_visible_fraction = min_visible_fraction
        self.min_box_px = min_box_px

    @classmethod
    def from_site(cls, site: Site, obstacles: Obstacles | None = None, **options: Unpack[RigOptions]) -> CameraRig:
        cams = [site.camera(c.id) for c in site.cameras]
        return cls(cams, [c.monitored_radius_m for c in site.cameras], obstacles, **options)

    def monitored(self, feet_xy: FloatArray) -> BoolArray:
        """(N, C): whether each floor point lies in each camera's monitored circle."""
        feet_xy = np.asarray(feet_xy, dtype=np.float64).reshape(-1, 2)
        out = np.ones((len(feet_xy), len(self.cameras)), dtype=bool)
        for c, (cam, radius) in enumerate(zip(self.cameras, self.monitored_radius_m, strict=True)):
            if radius is not None:
                out[:, c] = np.linalg.norm(feet_xy - cam.center[:2], axis=1) <= radius
        return out

    def observe(self, frame: SceneFrame) -> list[CameraView]:
        """One ``CameraView`` per camera, in camera order."""
        if not len(frame):
            return [CameraView.empty(c) for c in range(len(self.cameras))]
        prims = frame.primitives()
        samples = prims.surface_samples(self.points_per_body)
        lower = np.isin(samples.part, LOWER_PARTS)
        scaled = prims.axes / prims.radii[..., None, :]  # A diag(1/r)
        quadrics = np.einsum("npik,npjk->npij", scaled, scaled)  # Q = A diag(1/r²) Aᵀ: inside ⇔ xᵀQx ≤ 1
        return [
            self._observe_one(c, frame, prims, quadrics, samples.points, samples.normals, lower)
            for c in range(len(self.cameras))
        ]

    def _observe_one(
        self,
        c: int,
        frame: SceneFrame,
        prims: BodyPrimitives,
        quadrics: FloatArray,
        points: FloatArray,
        normals: FloatArray,
        lower: BoolArray,
    ) -> CameraView:
        cam, radius = self.cameras[c], self.monitored_radius_m[c]
        origin = cam.center
        dist = np.linalg.norm(frame.feet_xy - origin[:2], axis=1)
        near = np.flatnonzero(dist <= radius + _OCCLUDER_MARGIN_M) if radius is not None else np.arange(len(frame))
        if not len(near):
            return CameraView.empty(c)
        pts, nrm = points[near], normals[near]
        n, k = pts.shape[:2]
        facing = ((origin - pts) * nrm).sum(-1) > 0.0
        px = cam.project(pts.reshape(-1, 3)).reshape(n, k, 2)
        usable = facing & cam.in_image(px.reshape(-1, 2)).reshape(n, k)
        boxes = _masked_boxes(px, usable)
        candidate = usable.any(1) & ((dist[near] <= radius) if radius is not None else True)
        hidden = self._hidden_by_people(origin, pts, px, usable, prims, quadrics, near, boxes, candidate)
        hidden |= self._hidden_by_obstacles(origin, pts, usable, frame.feet_xy[near], candidate)
        visible = usable & ~hidden
        n_facing = np.maximum(facing.sum(1), 1)
        fraction = visible.sum(1) / n_facing
        lower_fraction = visible[:, lower].sum(1) / np.maximum(facing[:, lower].sum(1), 1)
        seen = _masked_boxes(px, visible)
        w, h = cam.image_size
        seen = np.clip(seen, 0.0, [w - 1, h - 1, w - 1, h - 1])
        size_ok = np.minimum(seen[:, 2] - seen[:, 0], seen[:, 3] - seen[:, 1]) >= self.min_box_px
        keep = np.flatnonzero(candidate & (fraction >= self.min_visible_fraction) & size_ok)
        rows = near[keep]
        return CameraView(
            camera_index=c,
            boxes=Boxes(xyxy=seen[keep]),
            person_ids=frame.person_ids[rows],
            visible_fraction=fraction[keep],
            lower_occluded=lower_fraction[keep] < 0.5,
            feet_xy=frame.feet_xy[rows],
            in_sight_ids=frame.person_ids[near[candidate & visible.any(1)]],
        )

    def _hidden_by_people(
        self,
        origin: FloatArray,
        pts: FloatArray,
        px: FloatArray,
        usable: BoolArray,
        prims: BodyPrimitives,
        quadrics: FloatArray,
        near: IntArray,
        boxes: FloatArray,
        candidate: BoolArray,
    ) -> BoolArray:
        """(n, K): points of candidate bodies whose ray from the camera crosses another body.
        Only a point that falls inside another body's image box can be hidden by it, so the exact
        ray–ellipsoid test runs on those (point, body) pairs alone."""
        n = len(near)
        hidden = np.zeros(pts.shape[:2], dtype=bool)
        a, b = np.nonzero(_boxes_overlap(boxes, boxes) & candidate[:, None] & ~np.eye(n, dtype=bool))
        if not len(a):
            return hidden
        dist = np.linalg.norm(pts - origin, axis=-1)
        nearest = np.where(usable, dist, np.inf).min(1)
        inside = usable[a] & (dist[a] > nearest[b, None])  # only what lies beyond b can hide behind it
        inside &= (px[a, :, 0] >= boxes[b, 0:1]) & (px[a, :, 0] <= boxes[b, 2:3])
        inside &= (px[a, :, 1] >= boxes[b, 1:2]) & (px[a, :, 1] <= boxes[b, 3:4])
        pair, k = np.nonzero(inside)
        if not len(pair):
            return hidden
        body, other = a[pair], b[pair]
        # Ellipsoid (c, Q = A diag(1/r²) Aᵀ); the ray o + t·d (t = 1 at the point) enters it where
        # dᵀQd t² + 2 dᵀQ(o − c) t + (o − c)ᵀQ(o − c) − 1 = 0.
        quad = quadrics[near]
        rel = origin - prims.centers[near]
        q_rel = np.einsum("npij,npj->npi", quad, rel)
        qc = np.einsum("npi,npi->np", q_rel, rel)[other] - 1.0
        d = pts[body, k] - origin  # (T, 3)
        qa = np.einsum("tpij,ti,tj->tp", quad[other], d, d)
        qb = 2.0 * np.einsum("tpi,ti->tp", q_rel[other], d)
        disc = qb * qb - 4.0 * qa * qc
        root = np.sqrt(np.maximum(disc, 0.0))
        t_in, t_out = (-qb - root) / (2 * qa), (-qb + root) / (2 * qa)
        hit = ((disc > 0) & (t_in < 1.0) & (t_out > 0.0)).any(-1)
        hidden[body[hit], k[hit]] = True
        return hidden

    def _hidden_by_obstacles(
        self, origin: FloatArray, pts: FloatArray, usable: BoolArray, feet_xy: FloatArray, candidate: BoolArray
    ) -> BoolArray:
        """(n, K): points whose ray from the camera crosses a pillar or shelf. On the floor plan,
        an obstacle can only hide a body if it comes near the line from below the camera to the
        body, so only such bodies are ray-tested."""
        hidden = np.zeros(pts.shape[:2], dtype=bool)
        if not len(self.obstacles):
            return hidden
        below = np.broadcast_to(origin[:2], feet_xy.shape)
        near = self.obstacles.near_segments(below, feet_xy, _BODY_REACH_M) & candidate[:, None]
        near_any: BoolArray = np.any(near, axis=1)
        body, k = np.nonzero(usable & near_any[:, None])
        if len(body):
            hidden[body, k] = self.obstacles.blocks_rays(origin, pts[body, k], only=near[body])
        return hidden


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """The people inside the monitored area in one frame: their ground-truth ``track_ids`` (as
    the paper counts tracks), scene ``person_ids`` and ``feet_xy``."""

    track_ids: IntArray
    person_ids: IntArray
    feet_xy: FloatArray


class GroundTruthTracks:
    """Ground-truth tracks as the paper counts them: someone who leaves the monitored area (the
    union of the cameras' circles) and comes back starts a new track, even without leaving the
    floor. Feed frames in order."""

    def __init__(self, rig: CameraRig) -> None:
        self.rig = rig
        self._track_of: dict[int, int] = {}  # person id → track id, for those inside last frame
        self._next = 1

    def update(self, frame: PeopleOnFloor) -> GroundTruth:
        inside = self.rig.monitored(frame.feet_xy).any(1) if len(frame.person_ids) else np.zeros(0, bool)
        track_of: dict[int, int] = {}
        for pid in frame.person_ids[inside].tolist():
            if pid in self._track_of:
                track_of[pid] = self._track_of[pid]
            else:
                track_of[pid], self._next = self._next, self._next + 1
        self._track_of = track_of
        ids = frame.person_ids[inside]
        return GroundTruth(np.array([track_of[p] for p in ids.tolist()], dtype=np.int64), ids, frame.feet_xy[inside])


def observe_scene(rig: CameraRig, scene: Scene) -> Iterator[tuple[SceneFrame, list[CameraView]]]:
    """Run a scene and yield each frame with what every camera saw of it."""
    for frame in scene.run():
        yield frame, rig.observe(frame)


def _masked_boxes(px: FloatArray, mask: BoolArray) -> FloatArray:
    """(n, K, 2) pixels and (n, K) mask → (n, 4) boxes of the masked pixels (NaN where none)."""
    x, y = px[..., 0], px[..., 1]
    out = np.stack(
        [np.where(mask, x, np.inf).min(1), np.where(mask, y, np.inf).min(1),
         np.where(mask, x, -np.inf).max(1), np.where(mask, y, -np.inf).max(1)], 1
    )  # fmt: skip
    out[~mask.any(1)] = np.nan
    return out


def _boxes_overlap(p: FloatArray, q: FloatArray) -> BoolArray:
    """(P, 4) × (Q, 4) → (P, Q) whether the boxes intersect (NaN boxes intersect nothing)."""
    return (
        (p[:, None, 0] <= q[None, :, 2])
        & (q[None, :, 0] <= p[:, None, 2])
        & (p[:, None, 1] <= q[None, :, 3])
        & (q[None, :, 1] <= p[:, None, 3])
    )
