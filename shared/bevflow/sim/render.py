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
so people keep their clothes from frame to frame (``bevflow.sim.render_feed`` does both for every
camera of a site). The static part of the scene is traced once per renderer, and shaded (and,
for a style without random sensor faults, finished) once per style; each ``render`` call traces,
shades and finishes only the pixels near people (their projected bounding boxes), all bodies in
one vectorised pass, so a 507 px frame of 50 people costs about 15 ms.

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
from bevflow.sim.render_rays import ellipsoid_normals, ray_box, ray_ellipsoids, ray_pillar, trace_bodies
from bevflow.sim.render_textures import Appearance, RenderStyle, finish_image, finish_pixels
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


@dataclass(frozen=True, eq=False)
class _StaticLook:
    """The static scene under one style: albedo and shaded colour per pixel, and the finished
    8-bit image when the style adds no random sensor faults."""

    style: RenderStyle
    albedo: FloatArray
    linear: FloatArray
    finished: NDArray[np.uint8] | None


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
        d = self.rays
        # Products of each ray's components, so a body's ellipsoids test a ray with one dot product.
        products = [d[:, 0] ** 2, d[:, 1] ** 2, d[:, 2] ** 2, d[:, 0] * d[:, 1], d[:, 0] * d[:, 2], d[:, 1] * d[:, 2]]
        self._ray_products = np.stack(products, 1).astype(np.float32)
        self._rays32 = d.astype(np.float32)
        self._look_cache: _StaticLook | None = None
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
            t, nrm = ray_pillar(o, d, p)
            closer = self.valid & (t < depth)
            depth[closer], material[closer], normal[closer], index[closer] = t[closer], _PILLAR, nrm[closer], k
        for k, s in enumerate(self.room.shelves):
            t, nrm, top = ray_box(o, d, s)
            closer = self.valid & (t < depth)
            depth[closer], normal[closer], index[closer] = t[closer], nrm[closer], k
            material[closer] = np.where(top[closer], _SHELF_TOP, _SHELF)
        if self.room.clutter:
            centers, axes, radii = _clutter_ellipsoids(self.room.clutter)
            t = ray_ellipsoids(o, d, centers, axes, radii)
            best = t.argmin(1)
            t_best = t[np.arange(n), best]
            closer = self.valid & (t_best < depth)
            hit = o + t_best[closer, None] * d[closer]
            normal[closer] = ellipsoid_normals(hit, centers[best[closer]], axes[best[closer]], radii[best[closer]])
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
        """Render N posed bodies (with their ``person_ids``) over the static scene.

        Only the pixels near a person are traced and shaded (every body at once); the rest of the
        frame is the static scene's, shaded once per style and, for a style without random
        sensor faults (no noise, blur or JPEG), even finished once."""
        rng = rng if rng is not None else np.random.default_rng(0)
        style = style if style is not None else RenderStyle.plain()
        n = len(bodies)
        person_ids = np.asarray(person_ids, dtype=np.int64).reshape(n)
        appearance = appearance if appearance is not None else Appearance.for_identities(person_ids)
        if len(appearance) != n:
            raise ValueError(f"appearance has {len(appearance)} people, the bodies {n}")
        static = self._static_look(style)
        h, w = self.shape
        owner = np.full(h * w, -1, dtype=np.int32)
        pix, who = self._body_pixels(bodies)
        t, part = trace_bodies(self.center, self._rays32[pix], self._ray_products[pix], bodies, who)
        silhouette = np.bincount(who[np.isfinite(t)], minlength=n)[:n]
        # The nearest body at each pixel, if it is nearer than the static scene.
        hit = np.flatnonzero(np.isfinite(t))
        order = hit[np.lexsort((t[hit], pix[hit]))]
        first = np.ones(len(order), dtype=bool)
        first[1:] = pix[order][1:] != pix[order][:-1]
        win = order[first]
        win = win[t[win] < self.static_depth[pix[win]]]
        sel, b, p = pix[win], who[win], part[win]
        owner[sel] = b
        # Shade the traced pixels: bodies where they won, the static scene elsewhere, all under
        # the people's floor shadows.
        touched, slot = np.unique(pix, return_inverse=True)
        shadow = np.ones(len(touched))
        self._cast_shadows(bodies, pix, who, slot, shadow, style)
        albedo = static.albedo[touched]
        normal = self.static_normal[touched]
        if len(win):
            c, a, r = bodies.centers[b, p], bodies.axes[b, p], bodies.radii[b, p]
            points = self.center + t[win, None].astype(np.float64) * self.rays[sel]
            k = slot[win]
            normal[k] = ellipsoid_normals(points, c, a, r)
            albedo[k] = appearance.albedo_of(b, p, np.einsum("ki,kij->kj", points - c, a) / r)
        light = style.ambient + style.diffuse * np.clip(normal @ style.light_dir, 0.0, None)
        linear = albedo * (light * shadow)[:, None]
        if static.finished is not None:
            image = static.finished.copy()
            image.reshape(-1, 3)[touched] = finish_pixels(linear, self.rim[touched], style)
        else:
            full = static.linear.copy()
            full[touched] = linear
            image = finish_image(full.reshape(h, w, 3), self.rim.reshape(h, w), style, rng)
        return self._with_boxes(image, owner.reshape(h, w), silhouette, person_ids, min_visible_fraction, min_pixels)

    def _static_look(self, style: RenderStyle) -> _StaticLook:
        if self._look_cache is None or self._look_cache.style is not style:
            # A live camera keeps its style: the static scene is shaded (and finished) once.
            albedo = self._static_albedo(style)
            light = style.ambient + style.diffuse * np.clip(self.static_normal @ style.light_dir, 0.0, None)
            linear = albedo * light[:, None]
            faults = style.noise_sigma > 0 or style.blur_sigma_px > 0 or style.jpeg_quality > 0
            h, w = self.shape
            finished = None if faults else finish_pixels(linear, self.rim, style).reshape(h, w, 3)
            self._look_cache = _StaticLook(style, albedo, linear, finished)
        return self._look_cache

    def _body_pixels(self, bodies: BodyPrimitives) -> tuple[IntArray, IntArray]:
        """Pairs (flat window index, body row) of the pixels each body may cover: its projected
        bounding box, padded, inside the lens."""
        h, w = self.shape
        x0, y0 = self.origin
        if not len(bodies):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        pts = bodies.surface_samples(96).points
        px = self.camera.project(pts.reshape(-1, 3)).reshape(len(bodies), -1, 2)
        seen: NDArray[np.bool_] = np.all(np.isfinite(px), axis=2)
        lo = np.where(seen[..., None], px, np.inf).min(1)
        hi = np.where(seen[..., None], px, -np.inf).max(1)
        pad = 2.0 + 0.1 * (hi - lo)
        with np.errstate(invalid="ignore"):
            start = np.floor(lo - pad - (x0, y0))
            stop = np.ceil(hi + pad - (x0, y0)) + 1
        ok: NDArray[np.bool_] = np.any(seen, axis=1)
        c0 = np.clip(np.where(ok, start[:, 0], 0), 0, w).astype(np.int64)
        r0 = np.clip(np.where(ok, start[:, 1], 0), 0, h).astype(np.int64)
        c1 = np.clip(np.where(ok, stop[:, 0], 0), 0, w).astype(np.int64)
        r1 = np.clip(np.where(ok, stop[:, 1], 0), 0, h).astype(np.int64)
        pix, who = [], []
        for b in np.flatnonzero((c1 > c0) & (r1 > r0)).tolist():
            idx = (np.arange(r0[b], r1[b])[:, None] * w + np.arange(c0[b], c1[b])).ravel()
            idx = idx[self.valid[idx]]
            pix.append(idx)
            who.append(np.full(len(idx), b, dtype=np.int64))
        if not pix:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(pix), np.concatenate(who)

    def _cast_shadows(
        self, bodies: BodyPrimitives, pix: IntArray, who: IntArray, slot: IntArray, shadow: FloatArray, style: RenderStyle
    ) -> None:
        """A soft dark blob on the floor under each body, pushed away from the light (on the
        floor pixels of the body's box; ``slot`` maps each pair to its pixel in ``shadow``)."""
        if style.shadow <= 0 or not len(pix):
            return
        on_floor = self.static_material[pix] == _FLOOR
        feet = bodies.centers[:, :, :2].mean(1) - 0.9 * style.light_dir[:2] / max(style.light_dir[2], 0.3)
        d2 = ((self.static_point[pix[on_floor], :2] - feet[who[on_floor]]) ** 2).sum(1)
        np.multiply.at(shadow, slot[on_floor], 1.0 - style.shadow * np.exp(-d2 / (2 * 0.28**2)))

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


def _clutter_ellipsoids(clutter: tuple[Clutter, ...]) -> tuple[FloatArray, FloatArray, FloatArray]:
    centers = np.array([[c.x, c.y, c.rz] for c in clutter], dtype=np.float64)
    radii = np.array([[c.rx, c.ry, c.rz] for c in clutter], dtype=np.float64)
    cos, sin = np.cos([c.heading for c in clutter]), np.sin([c.heading for c in clutter])
    axes = np.zeros((len(clutter), 3, 3))
    axes[:, 0, 0], axes[:, 1, 0], axes[:, 0, 1], axes[:, 1, 1], axes[:, 2, 2] = cos, sin, -sin, cos, 1.0
    return centers, axes, radii
