"""A rotation-aware person detector for ceiling fisheye frames: rim tiles turned upright through a
detector trained on ordinary photographs, boxes mapped back at their radial angle.

In a ceiling fisheye everyone lies along the radius, feet toward the image centre and head toward
the rim (the head is nearer the camera, so further off its axis). Above the centre they stand
upright, as in the photographs COCO detectors learnt from; elsewhere they lie sideways or upside
down, and such a detector misses them. So the frame is cut into ``tiles`` square tiles, each
turned about the image centre so that its sector stands upright above the centre: tile k covers
the radial angle 360° · k / tiles (``bevflow.detect.rotated``), from the centre out to the image
circle. Each tile's boxes come back as rotated boxes turned to their radial angle about the
centre, the way the person lies, with the sides the tile saw. A person between two tiles' angles
is boxed tilted by up to 22.5° in the nearer tile. Kept at the tile's angle, such boxes scored
AP50 0.31 to 0.85 on the real frames of docs/RESULTS.md turned five ways
(``bevflow.evaluation.turned``); turned to the radial angle, 0.64 to 0.86. AP50_rotated stayed
about where it was (mean 0.81 and 0.80, worst turn 0.73 and 0.67), and our renders under 5 m rose
from 0.60 to 0.73.

The pipeline gets each rotated box as its outline (``bevflow.detect.rotated.outline_xyxy``), the
upright box of the ellipse inside it, not its enclosing rectangle: the cylinder fit places the
feet from the upright box's corner nearest the centre, and a body does not fill the rectangle's
corners. On renders 3–5 m up (``bevflow.evaluation.placement``) walking and standing people are
placed 0.09–0.11 m from their feet (median) instead of 0.14–0.15 m. The centre model's boxes are
passed on as it gave them.

Tiles overlap. A box touching a tile's left or right edge is a person cut by it, whom the
neighbouring tile holds whole (a tile reaches further than half the angle to its neighbours at
every radius inside the circle), so such boxes are dropped; the rest are merged by rotated NMS.

People right under the camera are seen from above, which photographs hardly show and our renders
show plenty of; ``centre`` (optional) is a second detector for them, run on the frame at its
usual scale, whose boxes are kept within ``centre_share`` of the circle's radius and the tiles'
boxes outside it.

The layout (8 tiles of 0.8 × the radius from 0.1 × the radius out) suits ceilings of about 3 m,
where people are large in the frame; ``load_rim_tiles`` builds the detector with the shipped
FastestDet (``TILE_MODEL``: COCO's weights a quarter of the way to a fine-tune on our rendered
tiles, BSD-3-Clause: see the model card) on the tiles and the shipped render-trained model within
0.3 × the radius. It serves cameras under 5 m by default
(``bevflow.detect.runtime.DEFAULT_RANGES``): on real frames it finds most people, where the
render-trained models find few (docs/RESULTS.md, "Real frames").

**Small frames.** The tiles serve low-resolution cameras too: the real frames of docs/RESULTS.md
("Real frames"), shrunk from 2048 to 512 or 400 px (tiles enlarged 1.7 and 2.2 times), still
score AP50_rotated 0.80 and 0.81 through them, where the render-trained low-ceiling model scores
0.00. Our renders under 5 m, about as coarse, score 0.86 (0.78 with COCO's weights as published):
their people are rendered, not photographed, and so are the people the render-trained models
learnt.

**Threads.** FastestDet is small: on two ONNX Runtime threads each layer's work is too little to
share, and eight tiles took 32 ms on two threads against 46 ms on one. So each tile, and the
centre model's crop, is a job of its own for the first free of ``workers`` workers of one thread
each, one tile a call (four tiles in one call took 17 ms, one at a time 14.5: a batch's
activations outgrow the cache), the centre model's job first so that it runs beside the tiles.
On a 2048 px frame on a 2-core Intel Xeon that took 29–31 ms where two workers with four tiles
each and the centre model after them took 32–34 in the same runs (docs/BENCHMARKS.md has today's
figures).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, Unpack

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.circle import DEFAULT_FIELD_OF_VIEW_DEG
from bevflow.detect.coco import rotated_to_xyxy
from bevflow.detect.rotated import outline_xyxy, radial_angle, radial_boxes, rotated_iou_matrix
from bevflow.detections import Boxes

if TYPE_CHECKING:  # loaded only when a model loads, as in load_rim_tiles
    from bevflow.detect.runtime import Detector, DetectorOptions

FloatArray = NDArray[np.float64]
EDGE_PX = 2.0  # a box this close to a tile's side edge is cut by it
CENTRE_MARGIN_SHARE = 0.25  # of the radius: how far a person kept by the centre model may reach out
PREFILTER_SIGMA_PX = 0.5  # the smoothing before the warp shrinks a frame (prefiltered)
T = TypeVar("T")


@dataclass(frozen=True)
class TileLayout:
    """``tiles`` tiles of ``side_share`` × the circle radius, reaching from ``start_share`` ×
    the radius above the centre outward, each resized to the tile detector's input."""

    tiles: int = 8
    side_share: float = 0.8
    start_share: float = 0.1
    nms_iou: float = 0.4


class RimTileDetector:
    """``tile_detector``: a ``bevflow.detect.runtime.Detector`` with a fixed square input (e.g.
    FastestDet), given one tile a ``detect_scaled`` call. ``centre``: optional detector (with
    ``detect(image, height, focal)``) for the people right under the camera, run on the middle of
    the frame only. ``workers``: threads the tiles and the centre model's crop are shared among,
    each a job of its own (module docstring, "Threads")."""

    def __init__(self, tile_detector: Detector, layout: TileLayout = TileLayout(), centre: Detector | None = None,
                 centre_share: float = 0.3, field_of_view_deg: float = DEFAULT_FIELD_OF_VIEW_DEG,
                 workers: int = 1) -> None:  # fmt: skip
        hw = getattr(tile_detector, "fixed_hw", None)
        if hw is None or hw[0] != hw[1]:
            raise ValueError("the tile detector needs a fixed square input")
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.tile_detector, self.layout, self.centre = tile_detector, layout, centre
        self.workers = workers
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="rim-tiles") if workers > 1 else None
        self.centre_share, self.half_view = centre_share, math.radians(field_of_view_deg / 2)
        self.input_px = int(hw[0])

    @property
    def name(self) -> str:
        """How a site file names this detector: ``rim-tiles``, or ``rim-tiles:MODEL`` (the tile
        model's file name without ``.onnx``) where the tiles run another model than ``TILE_MODEL``."""
        path = getattr(self.tile_detector, "model_path", None)
        return RIM_TILES if path is None or Path(path).resolve() == TILE_MODEL else f"{RIM_TILES}:{Path(path).stem}"

    def detect(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
               centre: tuple[float, float] | None = None) -> Boxes:  # fmt: skip
        """Person boxes as the pipeline takes them (``detect_boxes``). ``centre``: the point people
        lie radially about (the camera's nadir in the image); default the middle of ``image_bgr``."""
        h, w = image_bgr.shape[:2]
        return self.detect_boxes(image_bgr, camera_height_m, focal_px, centre or ((w - 1) / 2, (h - 1) / 2))[0]

    def detect_rotated(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
                       centre: tuple[float, float]) -> tuple[FloatArray, FloatArray]:  # fmt: skip
        """Rotated boxes (N, 5) and their scores (``detect_boxes``)."""
        boxes, rotated = self.detect_boxes(image_bgr, camera_height_m, focal_px, centre)
        return rotated, boxes.confidence

    def detect_boxes(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
                     centre: tuple[float, float]) -> tuple[Boxes, FloatArray]:  # fmt: skip
        """The pipeline's upright boxes with their scores, and the same people's rotated boxes
        (N, 5); ``centre`` is the image circle's centre and its radius is ``focal_px`` times the
        lens's half view. A tile's person is boxed upright by the outline of their rotated box
        (``bevflow.detect.rotated.outline_xyxy``), the centre model's by its own box."""
        radius = focal_px * self.half_view
        k = self.tile_enlargement(radius)
        small = prefiltered(image_bgr, k)  # halved as far as it goes; the warp shrinks the rest
        k_small = small.shape[1] / image_bgr.shape[1]
        # The centre model's job goes first, so that it runs beside the tiles, not after them.
        middle = self._run(self._centre_boxes, image_bgr, small, k_small, camera_height_m, focal_px, centre) if self.centre else None
        rotated, conf = self._tiles(small, k_small, centre, radius)
        xyxy = outline_xyxy(rotated)
        if middle is not None:
            found, found_conf = middle.result()
            mid = radial_boxes(found, centre)
            near, inner = ~self.from_tiles(mid, focal_px, centre), self.from_tiles(rotated, focal_px, centre)
            rotated, xyxy = np.concatenate([rotated[inner], mid[near]]), np.concatenate([xyxy[inner], found[near]])
            conf = np.concatenate([conf[inner], found_conf[near]])
        return Boxes(xyxy, conf), rotated

    def from_tiles(self, rotated: FloatArray, focal_px: float, centre: tuple[float, float]) -> NDArray[np.bool_]:
        """Which of the rotated boxes (N, 5) lie where the tiles' boxes are kept, the rest being
        the centre model's: their centres at least ``centre_share`` of the circle's radius out."""
        return np.hypot(rotated[:, 0] - centre[0], rotated[:, 1] - centre[1]) >= self.centre_share * focal_px * self.half_view

    def _centre_boxes(self, image_bgr: NDArray[np.uint8], small: NDArray[np.uint8], k_small: float, camera_height_m: float,
                      focal_px: float, centre: tuple[float, float]) -> tuple[FloatArray, FloatArray]:  # fmt: skip
        """The centre model's upright boxes in frame pixels and their scores, from the middle of
        the frame only: a person kept there reaches at most a few tenths of the radius beyond
        ``centre_share``. The halved frame serves where the centre model shrinks it further
        anyway (rim tiles on cameras under about 8 m)."""
        assert self.centre is not None
        scale_for = getattr(self.centre, "scale_for", None)
        if scale_for is not None and scale_for(camera_height_m, focal_px) > k_small:
            small, k_small = image_bgr, 1.0
        half = int(math.ceil((self.centre_share + CENTRE_MARGIN_SHARE) * focal_px * self.half_view * k_small))
        cx, cy = int(centre[0] * k_small), int(centre[1] * k_small)
        x0, y0 = max(0, cx - half), max(0, cy - half)
        crop = np.ascontiguousarray(small[y0 : cy + half + 1, x0 : cx + half + 1])
        boxes = self.centre.detect(crop, camera_height_m, focal_px * k_small)
        return (boxes.xyxy + [x0, y0, x0, y0]) / k_small, boxes.confidence

    def _run(self, job: Callable[..., T], *args: Any) -> Future[T]:
        """``job(*args)`` on the workers, or here and now where there are none."""
        if self._pool is not None:
            return self._pool.submit(job, *args)
        done: Future[T] = Future()
        done.set_result(job(*args))
        return done

    def _detect_tiles(self, small: NDArray[np.uint8], maps: list[FloatArray]) -> list[Boxes]:
        """Each tile's boxes, in the order of ``maps`` (frame to tile), each tile a job of its own
        for the first free worker."""
        return [job.result() for job in [self._run(self._cut_and_detect, small, m) for m in maps]]

    def _cut_and_detect(self, small: NDArray[np.uint8], to_tile: FloatArray) -> Boxes:
        # One tile a call: four FastestDet tiles in one call took 17 ms, one at a time 14.5 (the
        # activations of a batch outgrow the cache).
        n = self.input_px
        tile = cv2.warpAffine(small, to_tile, (n, n), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        return self.tile_detector.detect_scaled(np.asarray(tile, dtype=np.uint8), 1.0)

    def tile_enlargement(self, radius: float) -> float:
        """How many times a frame's pixels are enlarged into the tiles, for an image circle of
        ``radius`` px (below 1: shrunk)."""
        return self.input_px / (self.layout.side_share * radius)

    def _tiles(self, small: NDArray[np.uint8], k_small: float, centre: tuple[float, float],
               radius: float) -> tuple[FloatArray, FloatArray]:  # fmt: skip
        """The tiles' rotated boxes in frame pixels; ``small`` is the frame at ``k_small`` times its size."""
        lay, n = self.layout, self.input_px
        k = self.tile_enlargement(radius)
        c = ((centre[0] + 0.5) * k_small - 0.5, (centre[1] + 0.5) * k_small - 0.5)
        angles = [2 * math.pi * t / lay.tiles for t in range(lay.tiles)]
        maps = [tile_affine(theta, c, radius * k_small, lay, n) for theta in angles]
        found, scores = [], []
        for (_, back, offset), boxes in zip(maps, self._detect_tiles(small, [m for m, _, _ in maps]), strict=True):
            x = boxes.xyxy
            whole = (x[:, 0] > EDGE_PX) & (x[:, 2] < n - 1 - EDGE_PX)
            x, conf = x[whole], boxes.confidence[whole]
            uv = np.column_stack([(x[:, 0] + x[:, 2]) / 2, (x[:, 1] + x[:, 3]) / 2])
            q = (uv - offset) / k  # tile pixels → frame pixels about the centre, turned upright
            p = np.asarray(centre) + q @ back.T
            found.append(np.column_stack([p, (x[:, 2] - x[:, 0]) / k, (x[:, 3] - x[:, 1]) / k, radial_angle(p[:, 0], p[:, 1], centre)]))
            scores.append(conf)
        rotated, conf = np.concatenate(found), np.concatenate(scores)
        keep = rotated_nms(rotated, conf, lay.nms_iou)
        return rotated[keep], conf[keep]


def prefiltered(image: NDArray[np.uint8], k: float) -> NDArray[np.uint8]:
    """``image`` made ready for the tiles' bilinear warp to shrink it ``k`` times (``k`` < 1):
    halved by area-averaging while ``k`` <= 0.5 (OpenCV's fast path), then, where some shrink is
    left to the warp, smoothed by a 3 × 3 Gaussian of σ 0.5 px so that the warp does not alias.
    On a 2048 px frame (2 threads) that takes 1 ms, where an area resize to exactly ``k`` took
    5.2 (4.4 of them for its fractional step), and the real frames of docs/RESULTS.md score alike
    either way; without the smoothing their AP50 falls from 0.85 to 0.81."""
    while k <= 0.5 and min(image.shape[:2]) >= 2:
        image = np.asarray(cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA), dtype=np.uint8)
        k *= 2
    return np.asarray(cv2.GaussianBlur(image, (3, 3), PREFILTER_SIGMA_PX), dtype=np.uint8) if k < 1 else image


def tile_affine(theta: float, centre: tuple[float, float], radius: float, layout: TileLayout,
                input_px: int) -> tuple[FloatArray, FloatArray, FloatArray]:  # fmt: skip
    """The 2 × 3 map from a frame (image circle ``centre`` and ``radius`` in its pixels) to the
    tile at radial angle ``theta`` (radians), turned so that its sector stands upright above the
    centre; with the turn back to the frame (2 × 2) and where the centre lies in tile pixels."""
    k = input_px / (layout.side_share * radius)
    back = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])  # tile → frame turn
    offset = np.array([input_px / 2, input_px + layout.start_share * radius * k])  # the centre, below the tile
    m = np.hstack([k * back.T, (offset - k * back.T @ np.asarray(centre, np.float64))[:, None]])
    return m, back, offset


RIM_TILES = "rim-tiles"
"""The name that selects this detector wherever a model is named (site file, ``--model``);
``rim-tiles:MODEL`` runs MODEL on the tiles instead of ``TILE_MODEL`` (``rim_tiles_model``)."""
TILE_MODEL = Path(__file__).resolve().parent.parent / "data" / "models" / "fastestdet-tiles.onnx"
"""FastestDet's COCO weights moved a quarter of the way toward a fine-tune on our rendered tiles
(BSD-3-Clause, see the model card): as good on real frames turned every way as the COCO weights
(``fastestdet-coco.onnx``, also shipped), better on renders. A tile costs a third to a quarter of
what YOLOX-nano (``yolox-nano-coco.onnx``, also shipped, more accurate on real frames) costs."""
CENTRE_MODEL = TILE_MODEL.with_name("bevflow-person-centernet.onnx")


def is_rim_tiles(name: str | Path | None) -> bool:
    """Whether a model name asks for the rim tiles: ``rim-tiles`` or ``rim-tiles:MODEL``."""
    return name is not None and (str(name) == RIM_TILES or str(name).startswith(f"{RIM_TILES}:"))


def rim_tiles_model(name: str | Path) -> str | None:
    """The tile model a rim-tiles name asks for: MODEL of ``rim-tiles:MODEL`` (a model file, or
    where models are named in a site file a shipped model's name, e.g. ``yolox-nano-coco``), None
    for ``rim-tiles`` (``TILE_MODEL``). ValueError for a name that asks for no rim tiles or for
    ``rim-tiles:`` with no model after it."""
    if not is_rim_tiles(name):
        raise ValueError(f"{name!r} does not name the rim tiles ({RIM_TILES} or {RIM_TILES}:MODEL)")
    text = str(name)
    if text == RIM_TILES:
        return None
    model = text.removeprefix(f"{RIM_TILES}:").strip()
    if not model:
        raise ValueError(f"{text!r} names no tile model: write {RIM_TILES}:MODEL, e.g. {RIM_TILES}:yolox-nano-coco")
    return model


def rim_tiles(model: Callable[[Path, int], Detector], threads: int, tile_model: str | Path | None = None) -> RimTileDetector:
    """The rim-tile detector with the shipped tile model (or ``tile_model``) on every tile and the
    shipped general model for the people right under the camera, each a job for one of
    ``threads`` workers of one ONNX Runtime thread; ``model(path, threads)`` loads each (and may
    share what it loaded with other cameras)."""
    return RimTileDetector(model(Path(tile_model or TILE_MODEL), 1), centre=model(CENTRE_MODEL, 1), workers=threads)


def load_rim_tiles(threads: int = 2, tile_model: str | Path | None = None, **options: Unpack[DetectorOptions]) -> RimTileDetector:
    """``rim_tiles`` with each model loaded on its own; ``options`` go to both."""
    from bevflow.detect.runtime import Detector  # onnxruntime is imported only when a model loads

    return rim_tiles(lambda path, n: Detector(path, threads=n, **options), threads, tile_model)


def rotated_nms(rotated: FloatArray, scores: FloatArray, iou_threshold: float) -> NDArray[np.int64]:
    """Greedy non-maximum suppression by rotated IoU; the indices kept, best score first. Only
    kept boxes are compared with the rest, and only with those whose enclosing boxes overlap
    theirs, so the cost follows the people who stand close, not the candidates."""
    order = np.argsort(-np.asarray(scores), kind="stable")
    boxes = np.asarray(rotated, np.float64).reshape(-1, 5)[order]
    e = rotated_to_xyxy(boxes)
    touch = (
        (e[:, None, 0] < e[None, :, 2]) & (e[None, :, 0] < e[:, None, 2])
        & (e[:, None, 1] < e[None, :, 3]) & (e[None, :, 1] < e[:, None, 3])
    )  # fmt: skip
    alive = np.ones(len(order), dtype=bool)
    keep = []
    for i in range(len(order)):
        if not alive[i]:
            continue
        keep.append(order[i])
        rest = np.nonzero(alive[i + 1 :] & touch[i, i + 1 :])[0] + i + 1
        if len(rest):
            alive[rest] &= rotated_iou_matrix(boxes[i], boxes[rest])[0] <= iou_threshold
    return np.asarray(keep, dtype=np.int64)
