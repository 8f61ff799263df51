"""A ray-casting renderer of ceiling fisheye frames: floors, walls, occluders and people.

Every pixel of the camera (or of a window of it) is traced through the project's fisheye model
(``Camera.world_rays``), so the image bends exactly as the calibrated lens does. The ray meets,
nearest first: the floor (Z = 0, textured), the room's walls, pillars (vertical cylinders),
shelves and counters (boxes), clutter on the floor (ellipsoids: bags, chairs, plants) and the
people's 14 ellipsoid body parts (``bevflow.sim.bodies``). Shading is Lambert with one
directional light plus ambient, with a soft floor shadow under each person; ``finish_image``
adds what a real camera adds (exposure, vignetting, blur, noise, JPEG).

Ground truth comes from the rendered id buffer: a person's box is the bounding box of the pixels
where that person is the nearest surface, so anything in front (another person, a shelf) cuts
the box, as in ``bevflow.sim.views``. People with less than ``min_visible_fraction`` of their
silhouette visible, or fewer than ``min_pixels`` visible pixels, get no box (they still appear
in the image and in ``owner``). Boxes are in pixel-centre coordinates (pixel (0, 0) covers
[-0.5, 0.5]²), the convention of the camera model.

For a live camera, render straight at the detector's input scale (``Camera.scaled`` with
``bevflow.detect.scaling.scale_factor``) and pass ``Appearance.for_identities(frame.identity)``
so people keep their clothes from frame to frame. The static part of the scene is traced once per renderer; each ``render`` call traces only the
pixels near each person (their projected bounding box), so a crowded 512 px frame costs tens of
milliseconds.

>>> from bevflow.camera import FisheyeCamera
>>> from bevflow.sim.bodies import BodyShape, pose_bodies
>>> cam = FisheyeCamera.looking_down((0.0, 0.0, 3.3), (240, 240))
>>> renderer = FisheyeRenderer(cam, Room(floor=(-6.0, -6.0, 6.0, 6.0)))
>>> bodies = pose_bodies(BodyShape.standard(1), np.array([[1.0, 0.5]]), np.zeros(1), np.zeros(1), np.zeros(1), np.ones(1, int))
>>> out = renderer.render(bodies, np.array([7]))
>>> out.image.shape, out.person_ids.tolist(), len(out.boxes)
((240, 240, 3), [7], 1)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from bevflow.camera import Camera
from bevflow.detections import Boxes
from bevflow.sim.bodies import BodyPrimitives
from bevflow.sim.render_textures import Appearance, RenderStyle, finish_image
from bevflow.sim.scene import Pillar, SceneConfig, Shelf

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Material codes of the static trace.
_NONE, _FLOOR, _WALL, _PILLAR, _SHELF, _SHELF_TOP, _CLUTTER = range(7)


@dataclass(frozen=True)
class Clutter:
    """An ellipsoid object resting on the floor (a bag, a bin, a chair, a plant), centred at
    (x, y) with semi-axes (rx, ry, rz) and yaw ``heading`` (rad). It looks a little like a person
    from above, which is the point: the detector must learn to tell them apart."""

    x: float
    y: float
    rx: float
    ry: float
    rz: float
    heading: float = 0.0
    color_index: int = 0


@dataclass(frozen=True)
class Room:
    """The static scene: a rectangular ``floor`` (xmin, ymin, xmax, ymax) walled up to
    ``wall_height`` m, with pillars, shelves and clutter standing on it."""

    floor: tuple[float, float, float, float]
    wall_height: float = 4.0
    pillars: tuple[Pillar, ...] = ()
    shelves: tuple[Shelf, ...] = ()
    clutter: tuple[Clutter, ...] = ()

    @classmethod
    def from_scene(cls, config: SceneConfig, wall_height: float = 4.0, margin_m: float = 0.0) -> Room:
        x0, y0, x1, y1 = config.floor
        floor = (x0 - margin_m, y0 - margin_m, x1 + margin_m, y1 + margin_m)
        return cls(floor=floor, wall_height=wall_height, pillars=config.pillars, shelves=config.shelves)


@dataclass(frozen=True, eq=False)
class Rendering:
    """One rendered frame (or window of one). ``image`` is 8-bit BGR; ``owner`` (H, W) holds the
    row of the person each pixel shows (-1: none). ``boxes``, ``person_ids`` and
    ``visible_fraction`` are row-aligned, one row per person with a box; ``origin`` is the window's
    top-left pixel in the full image, whose coordinates the boxes use."""

    image: NDArray[np.uint8]
    owner: NDArray[np.int32]
    boxes: Boxes
    person_ids: IntArray
    visible_fraction: FloatArray
    origin: tuple[int, int] = (0, 0)
    rows: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))  # the person row of each box


class FisheyeRenderer:
    """Renders one camera (optionally a ``window`` (x0, y0, x1, y1) of its image, in pixels) of a
    ``Room``. Pixels farther than ``circle_radius_px`` from the principal point are black, as
    outside a real fisheye's image circle (default: half the shorter image side)."""

    def __init__(
        self,
        camera: Camera,
        room: Room,
        window: tuple[int, int, int, int] | None = None,
        circle_radius_px: float | None = None,
    ) -> None:
        w, h = camera.image_size
        x0, y0, x1, y1 = window if window is not None else (0, 0, w, h)
        if x1 <= x0 or y1 <= y0:
            raise ValueError(f"window {window} is empty")
        self.camera, self.room = camera, room
        self.origin = (int(x0), int(y0))
        self.shape = (int(y1 - y0), int(x1 - x0))
        u, v = np.meshgrid(np.arange(x0, x1, dtype=np.float64), np.arange(y0, y1, dtype=np.float64))
        px = np.stack([u.ravel(), v.ravel()], 1)
        radius = circle_radius_px if circle_radius_px is not None else min(w, h) / 2.0
        rim = np.hypot(px[:, 0] - camera.K[0, 2], px[:, 1] - camera.K[1, 2]) / radius
        rays = camera.world_rays(px)
        valid = np.isfinite(rays).all(1) & (rim <= 1.0)
        self.rim = np.where(valid, rim, np.nan)
        self.rays = np.where(valid[:, None], rays, 0.0)
        self.valid = valid
        self.center = camera.center
        self._albedo_cache: tuple[RenderStyle, FloatArray] | None = None
        self._trace_static()

    # --- static scene ----------------------------------------------------------------------------
    def _trace_static(self) -> None:
        o, d = self.center, self.rays
        n = len(d)
        depth = np.full(n, np.inf)
        material = np.full(n, _NONE, dtype=np.int64)
        normal = np.zeros((n, 3))
        index = np.zeros(n, dtype=np.int64)
        x0, y0, x1, y1 = self.room.floor
        with np.errstate(divide="ignore", invalid="ignore"):
            t_floor = np.where(d[:, 2] < -1e-9, -o[2] / d[:, 2], np.inf)
            tx = np.where(d[:, 0] > 0, (x1 - o[0]) / d[:, 0], np.where(d[:, 0] < 0, (x0 - o[0]) / d[:, 0], np.inf))
            ty = np.where(d[:, 1] > 0, (y1 - o[1]) / d[:, 1], np.where(d[:, 1] < 0, (y0 - o[1]) / d[:, 1], np.inf))
        t_wall = np.minimum(tx, ty)
        floor_hit = self.valid & (t_floor <= t_wall)
        depth[floor_hit], material[floor_hit], normal[floor_hit] = t_floor[floor_hit], _FLOOR, (0.0, 0.0, 1.0)
        wall_hit = self.valid & ~floor_hit & np.isfinite(t_wall)
        depth[wall_hit], material[wall_hit] = t_wall[wall_hit], _WALL
        wall_normal = np.where((tx < ty)[:, None], [[-1.0, 0.0, 0.0]], [[0.0, -1.0, 0.0]]) * np.sign(
            np.where((tx < ty)[:, None], d[:, :1], d[:, 1:2])
        )
        normal[wall_hit] = wall_normal[wall_hit]
        for k, p in enumerate(self.room.pillars):
            t, nrm = _ray_pillar(o, d, p)
            closer = self.valid & (t < depth)
            depth[closer], material[closer], normal[closer], index[closer] = t[closer], _PILLAR, nrm[closer], k
        for k, s in enumerate(self.room.shelves):
            t, nrm, top = _ray_box(o, d, s)
            closer = self.valid & (t < depth)
            depth[closer], normal[closer], index[closer] = t[closer], nrm[closer], k
            material[closer] = np.where(top[closer], _SHELF_TOP, _SHELF)
        if self.room.clutter:
            centers, axes, radii = _clutter_ellipsoids(self.room.clutter)
            t = _ray_ellipsoids(o, d, centers, axes, radii)
            best = t.argmin(1)
            t_best = t[np.arange(n), best]
            closer = self.valid & (t_best < depth)
            hit = o + t_best[closer, None] * d[closer]
            normal[closer] = _ellipsoid_normals(hit, centers[best[closer]], axes[best[closer]], radii[best[closer]])
            depth[closer], material[closer], index[closer] = t_best[closer], _CLUTTER, best[closer]
        self.static_depth, self.static_material, self.static_normal, self.static_index = depth, material, normal, index
        self.static_point = o + np.where(np.isfinite(depth), depth, 0.0)[:, None] * d

    def _static_albedo(self, style: RenderStyle) -> FloatArray:
        m, pts = self.static_material, self.static_point
        albedo = np.zeros((len(m), 3))
        floor = m == _FLOOR
        albedo[floor] = style.floor_albedo(pts[floor, :2])
        for code, color in ((_WALL, style.wall_color), (_PILLAR, style.pillar_color), (_SHELF, style.shelf_color)):
            sel = m == code
            tex = style.texture_at(pts[sel][:, [0, 2]] / 0.05 + pts[sel][:, [1, 1]] / 0.05)
            albedo[sel] = np.clip(color * (1 + 0.08 * tex[:, None]), 0, 1)
        top = m == _SHELF_TOP  # goods on the shelves: busy, colourful texture
        tex = style.texture_at(pts[top, :2] / 0.02)
        hue = (tex[:, None] * np.array([3.0, 5.0, 7.0])) % 1.0
        albedo[top] = 0.5 * style.shelf_color + 0.5 * hue
        sel = m == _CLUTTER
        albedo[sel] = style.clutter_colors[self.static_index[sel] % len(style.clutter_colors)]
        return albedo

    # --- people ----------------------------------------------------------------------------------
    def render(
        self,
        bodies: BodyPrimitives,
        person_ids: IntArray,
        appearance: Appearance | None = None,
        style: RenderStyle | None = None,
        rng: np.random.Generator | None = None,
        min_visible_fraction: float = 0.25,
        min_pixels: int = 6,
    ) -> Rendering:
        """Render N posed bodies (with their ``person_ids``) over the static scene."""
        rng = rng if rng is not None else np.random.default_rng(0)
        style = style if style is not None else RenderStyle.plain()
        n = len(bodies)
        person_ids = np.asarray(person_ids, dtype=np.int64).reshape(n)
        appearance = appearance if appearance is not None else Appearance.for_identities(person_ids)
        if len(appearance) != n:
            raise ValueError(f"appearance has {len(appearance)} people, the bodies {n}")
        depth = self.static_depth.copy()
        if self._albedo_cache is None or self._albedo_cache[0] is not style:
            # A live camera keeps its style: its static colours are computed once.
            self._albedo_cache = (style, self._static_albedo(style))
        albedo = self._albedo_cache[1].copy()
        normal = self.static_normal.copy()
        owner = np.full(len(depth), -1, dtype=np.int32)
        silhouette = np.zeros(n, dtype=np.int64)
        shadow = np.ones(len(depth))
        floor = self.static_material == _FLOOR
        for b, idx in enumerate(self._body_pixels(bodies)):
            if not len(idx):
                continue
            self._cast_shadow(bodies, b, idx, floor, shadow, style)
            silhouette[b] = self._draw_body(bodies, b, idx, depth, albedo, normal, owner, appearance)
        light = style.ambient + style.diffuse * np.clip(normal @ style.light_dir, 0.0, None)
        linear = albedo * (light * shadow)[:, None]
        h, w = self.shape
        image = finish_image(linear.reshape(h, w, 3), self.rim.reshape(h, w), style, rng)
        return self._with_boxes(image, owner.reshape(h, w), silhouette, person_ids, min_visible_fraction, min_pixels)

    def _body_pixels(self, bodies: BodyPrimitives) -> list[IntArray]:
        """Flat window indices of the pixels each body may cover: its projected bounding box."""
        h, w = self.shape
        x0, y0 = self.origin
        if not len(bodies):
            return []
        pts = bodies.surface_samples(96).points
        px = self.camera.project(pts.reshape(-1, 3)).reshape(len(bodies), -1, 2)
        out = []
        for b in range(len(bodies)):
            p = px[b][np.isfinite(px[b]).all(1)]
            if not len(p):
                out.append(np.zeros(0, np.int64))
                continue
            lo, hi = p.min(0), p.max(0)
            pad = 2.0 + 0.1 * (hi - lo)
            c0, r0 = np.floor(lo - pad - (x0, y0)).astype(int)
            c1, r1 = np.ceil(hi + pad - (x0, y0)).astype(int) + 1
            c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, w), min(r1, h)
            if c1 <= c0 or r1 <= r0:
                out.append(np.zeros(0, np.int64))
                continue
            rr, cc = np.mgrid[r0:r1, c0:c1]
            idx = (rr * w + cc).ravel()
            out.append(idx[self.valid[idx]])
        return out

    def _draw_body(
        self,
        bodies: BodyPrimitives,
        b: int,
        idx: IntArray,
        depth: FloatArray,
        albedo: FloatArray,
        normal: FloatArray,
        owner: NDArray[np.int32],
        appearance: Appearance,
    ) -> int:
        """Trace body b's parts on its pixels; paint where it is nearest. Returns its silhouette
        size (pixels where the ray meets it at all, hidden or not)."""
        c, a, r = bodies.centers[b], bodies.axes[b], bodies.radii[b]
        d = self.rays[idx]
        t = _ray_ellipsoids(self.center, d, c, a, r)
        part = t.argmin(1)
        t_best = t[np.arange(len(idx)), part]
        hit = np.isfinite(t_best)
        near = hit & (t_best < depth[idx])
        sel, part = idx[near], part[near]
        points = self.center + t_best[near, None] * d[near]
        depth[sel], owner[sel] = t_best[near], b
        normal[sel] = _ellipsoid_normals(points, c[part], a[part], r[part])
        local = np.einsum("ki,kij->kj", points - c[part], a[part]) / r[part]
        for p in np.unique(part):
            rows = part == p
            albedo[sel[rows]] = appearance.part_albedo(b, int(p), local[rows])
        return int(hit.sum())

    def _cast_shadow(
        self, bodies: BodyPrimitives, b: int, idx: IntArray, floor: NDArray[np.bool_], shadow: FloatArray, style: RenderStyle
    ) -> None:
        """A soft dark blob on the floor under the body, pushed away from the light."""
        if style.shadow <= 0:
            return
        sel = idx[floor[idx]]
        feet = bodies.centers[b, :, :2].mean(0) - 0.9 * style.light_dir[:2] / max(style.light_dir[2], 0.3)
        d2 = ((self.static_point[sel, :2] - feet) ** 2).sum(1)
        shadow[sel] *= 1.0 - style.shadow * np.exp(-d2 / (2 * 0.28**2))

    def _with_boxes(
        self,
        image: NDArray[np.uint8],
        owner: NDArray[np.int32],
        silhouette: IntArray,
        person_ids: IntArray,
        min_visible_fraction: float,
        min_pixels: int,
    ) -> Rendering:
        n = len(person_ids)
        visible = np.bincount(owner[owner >= 0], minlength=n)[:n] if n else np.zeros(0, np.int64)
        fraction = visible / np.maximum(silhouette, 1)
        slices = ndimage.find_objects(owner + 1, max_label=n) if n else []
        keep = [b for b in range(n) if slices[b] is not None and visible[b] >= min_pixels and fraction[b] >= min_visible_fraction]
        x0, y0 = self.origin
        xyxy = np.array(
            [[slices[b][1].start + x0 - 0.5, slices[b][0].start + y0 - 0.5, slices[b][1].stop + x0 - 0.5, slices[b][0].stop + y0 - 0.5] for b in keep],
            dtype=np.float64,
        ).reshape(-1, 4)
        rows = np.asarray(keep, dtype=np.int64)
        return Rendering(image, owner, Boxes(xyxy=xyxy), person_ids[rows], fraction[rows], self.origin, rows)


def _ray_ellipsoids(o: FloatArray, d: FloatArray, centers: FloatArray, axes: FloatArray, radii: FloatArray) -> FloatArray:
    """Distances (K, P) along K rays from o to the first hit of P ellipsoids (inf: missed)."""
    to_unit = axes / radii[:, None, :]  # (P, 3, 3): world offsets to the unit sphere's frame
    o_local = np.einsum("pi,pij->pj", o - centers, to_unit)  # (P, 3)
    p = len(centers)
    d_local = (d @ to_unit.transpose(1, 0, 2).reshape(3, 3 * p)).reshape(len(d), p, 3)  # (K, P, 3)
    qa = np.einsum("kpj,kpj->kp", d_local, d_local)
    qb = 2.0 * np.einsum("kpj,pj->kp", d_local, o_local)
    qc = np.einsum("pj,pj->p", o_local, o_local) - 1.0
    disc = qb * qb - 4.0 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-qb - np.sqrt(disc)) / (2.0 * qa)
    return np.where((disc > 0) & (t > 1e-6), t, np.inf)


def _ellipsoid_normals(points: FloatArray, centers: FloatArray, axes: FloatArray, radii: FloatArray) -> FloatArray:
    local = np.einsum("ki,kij->kj", points - centers, axes) / radii**2
    n = np.einsum("kij,kj->ki", axes, local)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def _ray_pillar(o: FloatArray, d: FloatArray, p: Pillar) -> tuple[FloatArray, FloatArray]:
    """First hit of each ray with a vertical cylinder (side or top cap) and the surface normal."""
    rel = o[:2] - (p.x, p.y)
    a = (d[:, :2] ** 2).sum(1)
    b = 2.0 * d[:, :2] @ rel
    c = rel @ rel - p.radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t_side = (-b - np.sqrt(disc)) / (2 * a)
        z = o[2] + t_side * d[:, 2]
        side = (disc > 0) & (t_side > 0) & (z >= 0) & (z <= p.height)
        t_cap = (p.height - o[2]) / d[:, 2]
    t_cap = np.where(np.isfinite(t_cap), t_cap, -1.0)
    cap_xy = o[:2] + t_cap[:, None] * d[:, :2]
    cap = (t_cap > 0) & (((cap_xy - (p.x, p.y)) ** 2).sum(1) <= p.radius**2)
    t = np.where(side, t_side, np.inf)
    t = np.where(cap & (t_cap < t), t_cap, t)
    hit_xy = o[:2] + np.where(np.isfinite(t), t, 0.0)[:, None] * d[:, :2] - (p.x, p.y)
    side_normal = np.concatenate([hit_xy / p.radius, np.zeros((len(d), 1))], 1)
    normal = np.where((cap & (t == t_cap))[:, None], [[0.0, 0.0, 1.0]], side_normal)
    return t, normal


def _ray_box(o: FloatArray, d: FloatArray, s: Shelf) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """First hit of each ray with a box standing on the floor, its normal and whether it is the top."""
    lo = np.array([min(s.x0, s.x1), min(s.y0, s.y1), 0.0])
    hi = np.array([max(s.x0, s.x1), max(s.y0, s.y1), s.height])
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - o) / d, (hi - o) / d
    t_near = np.fmin(ta, tb)
    t_far = np.fmax(ta, tb)
    t_near = np.where(np.isnan(t_near), -np.inf, t_near)
    t_far = np.where(np.isnan(t_far), np.inf, t_far)
    axis = t_near.argmax(1)
    t_in, t_out = t_near.max(1), t_far.min(1)
    hit = (t_in < t_out) & (t_in > 0)
    normal = np.zeros((len(d), 3))
    normal[np.arange(len(d)), axis] = -np.sign(d[np.arange(len(d)), axis])
    return np.where(hit, t_in, np.inf), normal, axis == 2


def _clutter_ellipsoids(clutter: tuple[Clutter, ...]) -> tuple[FloatArray, FloatArray, FloatArray]:
    centers = np.array([[c.x, c.y, c.rz] for c in clutter], dtype=np.float64)
    radii = np.array([[c.rx, c.ry, c.rz] for c in clutter], dtype=np.float64)
    cos, sin = np.cos([c.heading for c in clutter]), np.sin([c.heading for c in clutter])
    axes = np.zeros((len(clutter), 3, 3))
    axes[:, 0, 0], axes[:, 1, 0], axes[:, 0, 1], axes[:, 1, 1], axes[:, 2, 2] = cos, sin, -sin, cos, 1.0
    return centers, axes, radii
