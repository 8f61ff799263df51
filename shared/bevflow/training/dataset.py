"""Training data for the person detector: rendered fisheye crops, or a user's COCO JSON.

Rendered samples are drawn straight at the detector's input scale (``bevflow.detect.scaling``):
a ceiling camera 3–10 m high whose focal length makes a person at the image centre about 20 px
across, jittered by ±15 % so the model tolerates an imprecise height or focal length. Only a
square window of the camera (``size`` px) is traced, somewhere inside the image circle, so a
sample costs the same at every height. Each sample keeps the rendered id buffer (``owner``):
rotating it with the image gives exact boxes after any rotation (``bevflow.training.augment``).

``owner`` values: a person's row (≥ 0) for people that have a box, ``IGNORE`` (-2) for people
too hidden to count (the loss neither rewards nor punishes a detection there), -1 elsewhere.

User data in COCO JSON is read by ``bevflow.detect.coco``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.camera import FisheyeCamera, rotation_from_ypr
from bevflow.detect.coco import write_coco
from bevflow.detect.scaling import SHOULDER_HEIGHT_M, TARGET_FOCAL_PER_M
from bevflow.sim.bodies import BodyShape, pose_bodies
from bevflow.sim.render import Clutter, FisheyeRenderer, Room
from bevflow.sim.render_textures import Appearance, RenderStyle
from bevflow.sim.scene import Pillar, Shelf

FloatArray = NDArray[np.float64]
IGNORE = -2


@dataclass(frozen=True, eq=False)
class RenderedSample:
    image: NDArray[np.uint8]  # (S, S, 3) BGR
    owner: NDArray[np.int16]  # (S, S)
    camera_height_m: float
    xyxy: FloatArray | None = None  # the boxes, in the whole frame's pixels even for a window
    focal_px: float | None = None  # the rendering camera's focal length


MOUNTING_HEIGHTS_M = (3.0, 10.0)


@dataclass(frozen=True)
class SceneMix:
    """Shares of the harder cases a render draws. All 0 (the default) draws exactly the renders
    drawn before these existed, so the seeds of older training sets still give the same data.

    - ``grouped``: of the people, standing in tight groups (``_groups``).
    - ``shifted_tiles``: of the tiled floors, laid with their grid off the camera
      (``RenderStyle.sample``).
    - ``squared``: of the cameras, mounted level and square to the room (yaw a multiple of 90°), as
      installers often do. The floor's grout lines then run along the pixel rows and columns,
      where a crisp line stays unbroken for many pixels.
    """

    grouped: float = 0.0
    shifted_tiles: float = 0.0
    squared: float = 0.0

    def __post_init__(self) -> None:
        for name in ("grouped", "shifted_tiles", "squared"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"SceneMix.{name} is a share, 0 to 1, got {getattr(self, name)}")


def render_sample(
    rng: np.random.Generator, size: int | None = 288, max_people: int = 30, zoom: float = 1.0, min_pixels: int = 6,
    heights: tuple[float, float] = MOUNTING_HEIGHTS_M, mix: SceneMix = SceneMix(), frame_px: int | None = None,
) -> RenderedSample:
    """One random window of ``size`` px (None: the whole frame) of a random ceiling fisheye frame
    at the detector's input scale times ``zoom`` (zoom > 1: a frame as a camera would deliver it,
    larger than the detector's input), from a camera hanging at a height drawn from ``heights``
    (metres, low and high). People with fewer than ``min_pixels`` visible pixels get no box (a
    person is some 300 px at the detector's scale). ``mix`` draws harder cases more often.
    ``frame_px``: the frame is that many pixels across whatever the height, as a camera's sensor
    gives it, the same scene as without it; ``min_pixels`` grows with the enlargement squared."""
    height = rng.uniform(*heights)
    cam = _random_camera(rng, height, zoom, mix.squared)
    w = cam.image_size[0]
    radius = w / 2.0
    if size is None:
        x0 = y0 = 0
        size = w
    elif w <= size:
        x0 = y0 = int(round((w - size) / 2))
    else:
        r = radius * math.sqrt(rng.uniform(0, 0.85))
        a = rng.uniform(0, 2 * math.pi)
        x0 = int(np.clip(radius + r * math.cos(a) - size / 2, 0, w - size))
        y0 = int(np.clip(radius + r * math.sin(a) - size / 2, 0, w - size))
    window = (x0, y0, x0 + size, y0 + size)
    floor_pts = _window_floor_points(rng, cam, window, radius)
    room = _random_room(rng, height, floor_pts)
    people_xy = _spread(rng, floor_pts, int(rng.integers(0, max_people + 1)) if rng.random() > 0.08 else 0, room, mix.grouped)
    n = len(people_xy)
    if frame_px is not None:  # the scene is drawn; only the picture of it is larger
        k = frame_px / w
        cam, radius, min_pixels = _resized(cam, frame_px), radius * k, int(min_pixels * k * k)
        wx0, wy0, wx1, wy1 = (int(round(v * k)) for v in window)
        window = (wx0, wy0, wx1, wy1)
    bodies = pose_bodies(
        BodyShape.sample(rng, n), people_xy, rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n),
        rng.uniform(0, 1.6, n), rng.choice(3, n, p=[0.6, 0.3, 0.1]),
    )  # fmt: skip
    renderer = FisheyeRenderer(cam, room, window=window, circle_radius_px=radius)
    out = renderer.render(bodies, np.arange(n), Appearance.sample(rng, n), RenderStyle.sample(rng, mix.shifted_tiles), rng,
                          min_pixels=min_pixels)
    owner = np.full(out.owner.shape, -1, dtype=np.int16)
    boxed = np.zeros(n + 1, dtype=bool)
    boxed[out.rows] = True
    people = out.owner >= 0
    owner[people] = np.where(boxed[out.owner[people]], out.owner[people], IGNORE)
    return RenderedSample(out.image, owner, float(height), out.boxes.xyxy, float(cam.K[0, 0]))


def _random_camera(rng: np.random.Generator, height: float, zoom: float = 1.0, squared: float = 0.0) -> FisheyeCamera:
    fov = rng.uniform(180.0, 200.0)
    dist = np.array([rng.uniform(-0.04, 0.01), rng.uniform(0.0, 0.003), 0.0, 0.0])
    focal = TARGET_FOCAL_PER_M * (height - SHOULDER_HEIGHT_M) * rng.uniform(0.85, 1.15) * zoom
    half = math.radians(fov / 2)
    probe = FisheyeCamera.looking_down((0.0, 0.0, height), (8, 8), fov, dist=tuple(dist))
    rim = float(probe.distort_theta(np.array(min(half, probe.max_theta))))
    size = int(math.ceil(2 * focal * rim))
    c = (size - 1) / 2.0
    K = np.array([[focal, 0.0, c], [0.0, focal, c], [0.0, 0.0, 1.0]])
    # Ceilings are not perfectly level: a few degrees of tilt.
    R = rotation_from_ypr(rng.uniform(0, 360), rng.normal(0, 1.5), rng.normal(0, 1.5))
    if squared > 0 and rng.random() < squared:
        R = rotation_from_ypr(90.0 * int(rng.integers(4)), 0.0, 0.0)
    return FisheyeCamera(K=K, dist=dist, R=R, t=-R @ np.array([0.0, 0.0, height]), image_size=(size, size))


def _resized(cam: FisheyeCamera, frame_px: int) -> FisheyeCamera:
    """``cam`` with a square frame of ``frame_px`` (its focal length and centre scaled with it)."""
    k = frame_px / cam.image_size[0]
    c = (frame_px - 1) / 2.0
    K = np.array([[cam.K[0, 0] * k, 0.0, c], [0.0, cam.K[1, 1] * k, c], [0.0, 0.0, 1.0]])
    return FisheyeCamera(K=K, dist=cam.dist, R=cam.R, t=cam.t, image_size=(frame_px, frame_px))


def _window_floor_points(rng: np.random.Generator, cam: FisheyeCamera, window: tuple[int, int, int, int], radius: float) -> FloatArray:
    """Floor points seen in (or just around) the window, inside the image circle."""
    x0, y0, x1, y1 = window
    px = rng.uniform([x0 - 20, y0 - 20], [x1 + 20, y1 + 20], (600, 2))
    c = cam.K[:2, 2]
    px = px[np.hypot(*(px - c).T) < radius * 0.97]
    pts = cam.pixels_to_plane(px, 0.0)[:, :2]
    pts = pts[np.isfinite(pts).all(1)]
    return pts[np.hypot(*pts.T) < 30.0] if len(pts) else np.zeros((1, 2))


def _semi_axes(rng: np.random.Generator) -> tuple[float, float, float]:
    rx, ry, rz = rng.uniform([0.1, 0.1, 0.1], [0.45, 0.35, 0.6]).tolist()
    return rx, ry, rz


def _random_room(rng: np.random.Generator, height: float, floor_pts: FloatArray) -> Room:
    lo = np.minimum(floor_pts.min(0), 0.0) - rng.uniform(0.5, 12.0, 2) * (rng.random(2) < 0.6) - 0.6
    hi = np.maximum(floor_pts.max(0), 0.0) + rng.uniform(0.5, 12.0, 2) * (rng.random(2) < 0.6) + 0.6
    # Walls only where a floor point is not already outside: keep the room around what is seen.
    lo, hi = np.minimum(lo, -1.0), np.maximum(hi, 1.0)

    def pick(k: int) -> FloatArray:
        return floor_pts[rng.integers(0, len(floor_pts), k)]

    pillars = tuple(Pillar(float(x), float(y), float(rng.uniform(0.15, 0.5)), float(rng.choice([height + 1, rng.uniform(1, 3)])))
                    for x, y in pick(int(rng.integers(0, 3))))  # fmt: skip
    shelves = []
    for x, y in pick(int(rng.integers(0, 3))):
        sx, sy = rng.uniform(0.4, 3.0), rng.uniform(0.4, 1.2)
        if rng.random() < 0.5:
            sx, sy = sy, sx
        shelves.append(Shelf(float(x), float(y), float(x + sx), float(y + sy), float(rng.uniform(0.5, 2.0))))
    clutter = tuple(
        Clutter(
            float(x),
            float(y),
            *_semi_axes(rng),
            heading=float(rng.uniform(0, np.pi)),
            color_index=int(rng.integers(0, 8)),
        )
        for x, y in pick(int(rng.integers(0, 7)))
    )
    return Room((float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), float(height + rng.uniform(-0.5, 1.0)),
                pillars, tuple(shelves), clutter)  # fmt: skip


def _spread(rng: np.random.Generator, floor_pts: FloatArray, n: int, room: Room, grouped: float = 0.0) -> FloatArray:
    """Up to n feet positions among the floor points, at least ~0.45 m apart, off the obstacles;
    about ``grouped`` of them first offered in tight groups (``_groups``)."""
    x0, y0, x1, y1 = room.floor
    shuffled = floor_pts[rng.permutation(len(floor_pts))]
    grouped_pts = _groups(rng, shuffled, round(grouped * n)) if grouped > 0 and n > 1 else np.zeros((0, 2))
    # Each single point's jitter is drawn only when it is offered, so ``grouped=0`` draws what it always did.
    offered = itertools.chain(grouped_pts, (p + rng.normal(0, 0.2, 2) for p in shuffled)) if n > 0 else ()
    chosen: list[FloatArray] = []
    for p in offered:
        if not (x0 + 0.3 < p[0] < x1 - 0.3 and y0 + 0.3 < p[1] < y1 - 0.3):
            continue
        if any(np.hypot(p[0] - q.x, p[1] - q.y) < q.radius + 0.3 for q in room.pillars):
            continue
        if any(min(s.x0, s.x1) - 0.3 < p[0] < max(s.x0, s.x1) + 0.3 and min(s.y0, s.y1) - 0.3 < p[1] < max(s.y0, s.y1) + 0.3 for s in room.shelves):
            continue
        if chosen and np.hypot(*(np.array(chosen) - p).T).min() < 0.45:
            continue
        chosen.append(p)
        if len(chosen) >= n:
            break
    return np.array(chosen, dtype=np.float64).reshape(-1, 2)


def _groups(rng: np.random.Generator, anchors: FloatArray, count: int) -> FloatArray:
    """At least ``count`` feet positions in groups of 2–5 people 0.47–0.65 m apart, each around one
    of ``anchors``: a queue in a line, or a huddle in a ring. In a ceiling view a queue running
    away from the camera stacks its people along one radial streak, where one box easily covers
    two of them."""
    out: list[FloatArray] = []
    for anchor in anchors:
        if sum(map(len, out)) >= count:
            break
        k, gap, turn = int(rng.integers(2, 6)), rng.uniform(0.47, 0.65), rng.uniform(0, 2 * np.pi)
        if rng.random() < 0.6:
            offsets = np.arange(k)[:, None] * gap * np.array([np.cos(turn), np.sin(turn)])
        else:
            angle = turn + 2 * np.pi * np.arange(k) / k
            offsets = gap / (2 * np.sin(np.pi / k)) * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        out.append(anchor + offsets + rng.normal(0, 0.02, (k, 2)))
    return np.concatenate(out) if out else np.zeros((0, 2))


def write_shard(path: Path, samples: list[RenderedSample]) -> None:
    """Save rendered samples as one compressed .npz (images, owners, heights)."""
    np.savez_compressed(
        path,
        images=np.stack([s.image for s in samples]),
        owners=np.stack([s.owner for s in samples]),
        heights=np.array([s.camera_height_m for s in samples]),
    )


def read_shards(folder: Path) -> tuple[NDArray[np.uint8], NDArray[np.int16], FloatArray]:
    files = sorted(f for f in Path(folder).glob("*.npz") if not f.name.endswith(".tmp.npz"))
    if not files:
        raise FileNotFoundError(f"no .npz shards in {folder}")
    parts = [np.load(f) for f in files]
    return (np.concatenate([p["images"] for p in parts]), np.concatenate([p["owners"] for p in parts]),
            np.concatenate([p["heights"] for p in parts]))  # fmt: skip


def render_dataset(folder: Path, count: int, seed: int = 0, shard_size: int = 50, log: object = None,
                   heights: tuple[float, float] = MOUNTING_HEIGHTS_M, mix: SceneMix = SceneMix(), zoom: float = 1.0) -> int:
    """Render ``count`` samples (cameras at ``heights``, harder cases as ``mix`` asks, at ``zoom``
    times the detector's scale, see ``render_sample``) into ``folder`` as shards of ``shard_size``. Shard k is drawn from the seed
    (seed, k), and existing shards are kept, so an interrupted run resumes where it stopped and
    gives the same data; shards of other seeds may share the folder. Returns the number of shards
    written now."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = 0
    for k in range(math.ceil(count / shard_size)):
        path = folder / f"shard-{seed:04d}-{k:05d}.npz"
        if path.exists():
            continue
        rng = np.random.default_rng([seed, k])
        n = min(shard_size, count - k * shard_size)
        write_shard(path.with_suffix(".tmp.npz"), [render_sample(rng, zoom=zoom, heights=heights, mix=mix) for _ in range(n)])
        path.with_suffix(".tmp.npz").rename(path)
        written += 1
        if callable(log):
            log(f"wrote {path.name} ({n} samples)")
    return written


def render_evaluation_set(folder: Path, count: int, seed: int = 1000, zoom: tuple[float, float] = (1.0, 1.4),
                          mix: SceneMix = SceneMix(), heights: tuple[float, float] = MOUNTING_HEIGHTS_M,
                          frame_px: int | None = None) -> Path:  # fmt: skip
    """Render ``count`` whole frames (cameras ``heights`` high, 3–10 m by default) as PNG files
    plus ``annotations.json`` (COCO, with ``camera_height_m`` and ``focal_px`` per image) into
    ``folder``; frames are ``zoom`` times the detector's input scale, so evaluating them
    exercises the resize too, or ``frame_px`` across (a camera's frame: the same scenes, sharper).
    Use a seed the training data did not use; ``mix`` as in ``render_sample``. Returns the
    annotation file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    images, boxes = [], []
    for k in range(count):
        rng = np.random.default_rng([seed, k])
        z = float(rng.uniform(*zoom))
        # Whole frames: slivers of people cut by the image circle's rim are not worth a box.
        sample = render_sample(rng, size=None, zoom=z, min_pixels=int(30 * z * z), heights=heights, mix=mix, frame_px=frame_px)
        name = f"frame-{k:05d}.png"
        cv2.imwrite(str(folder / name), sample.image)
        h, w = sample.image.shape[:2]
        images.append({"file_name": name, "width": w, "height": h, "camera_height_m": round(sample.camera_height_m, 3),
                       "focal_px": round(float(sample.focal_px or 0.0), 3)})  # fmt: skip
        boxes.append(sample.xyxy if sample.xyxy is not None else np.zeros((0, 4)))
    path = folder / "annotations.json"
    write_coco(path, images, boxes)
    return path
