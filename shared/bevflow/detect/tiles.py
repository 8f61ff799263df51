"""A rotation-aware person detector for ceiling fisheye frames: rim tiles turned upright through a
detector trained on ordinary photographs, boxes mapped back with their tile's angle.

In a ceiling fisheye everyone lies along the radius, feet toward the image centre and head toward
the rim (the head is nearer the camera, so further off its axis). Above the centre they stand
upright, as in the photographs COCO detectors learnt from; elsewhere they lie sideways or upside
down, and such a detector misses them. So the frame is cut into ``tiles`` square tiles, each
turned about the image centre so that its sector stands upright above the centre: tile k covers
the radial angle 360° · k / tiles (``bevflow.detect.rotated``), from the centre out to the image
circle. Each tile's boxes come back as rotated boxes at that angle.

Tiles overlap. A box touching a tile's left or right edge is a person cut by it, whom the
neighbouring tile holds whole (a tile reaches further than half the angle to its neighbours at
every radius inside the circle), so such boxes are dropped; the rest are merged by rotated NMS.

People right under the camera are seen from above, which photographs hardly show and our renders
show plenty of; ``centre`` (optional) is a second detector for them, run on the frame at its
usual scale, whose boxes are kept within ``centre_share`` of the circle's radius and the tiles'
boxes outside it.

The layout (8 tiles of 0.8 × the radius from 0.1 × the radius out) suits ceilings of about 3 m,
where people are large in the frame; ``load_rim_tiles`` builds the detector with the shipped
YOLOX-nano (COCO, Apache-2.0: see the model card) on the tiles and the shipped render-trained
model within 0.3 × the radius. On real frames it finds far more people than the shipped model
alone, at many times its cost (docs/RESULTS.md, "Real frames").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.circle import DEFAULT_FIELD_OF_VIEW_DEG
from bevflow.detect.coco import rotated_to_xyxy
from bevflow.detect.rotated import radial_boxes, rotated_iou_matrix
from bevflow.detections import Boxes

if TYPE_CHECKING:  # loaded only when a model loads, as in load_rim_tiles
    from bevflow.detect.runtime import Detector

FloatArray = NDArray[np.float64]
EDGE_PX = 2.0  # a box this close to a tile's side edge is cut by it


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
    FastestDet). ``centre``: optional detector (with ``detect(image, height, focal)``) for the
    people right under the camera."""

    def __init__(self, tile_detector: Detector, layout: TileLayout = TileLayout(), centre: Detector | None = None,
                 centre_share: float = 0.3, field_of_view_deg: float = DEFAULT_FIELD_OF_VIEW_DEG) -> None:  # fmt: skip
        hw = getattr(tile_detector, "fixed_hw", None)
        if hw is None or hw[0] != hw[1]:
            raise ValueError("the tile detector needs a fixed square input")
        self.tile_detector, self.layout, self.centre = tile_detector, layout, centre
        self.centre_share, self.half_view = centre_share, math.radians(field_of_view_deg / 2)
        self.input_px = int(hw[0])

    def detect(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
               centre: tuple[float, float] | None = None) -> Boxes:  # fmt: skip
        """Person boxes as the pipeline takes them: each rotated box's enclosing rectangle.
        ``centre``: the point people lie radially about (the camera's nadir in the image);
        default the middle of ``image_bgr``."""
        h, w = image_bgr.shape[:2]
        rotated, conf = self.detect_rotated(image_bgr, camera_height_m, focal_px, centre or ((w - 1) / 2, (h - 1) / 2))
        return Boxes(rotated_to_xyxy(rotated), conf)

    def detect_rotated(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
                       centre: tuple[float, float]) -> tuple[FloatArray, FloatArray]:  # fmt: skip
        """Rotated boxes (N, 5) and their scores; ``centre`` is the image circle's centre and its
        radius is ``focal_px`` times the lens's half view."""
        radius = focal_px * self.half_view
        rotated, conf = self._tiles(image_bgr, centre, radius)
        if self.centre is not None:
            inner = np.hypot(rotated[:, 0] - centre[0], rotated[:, 1] - centre[1]) >= self.centre_share * radius
            boxes = self.centre.detect(image_bgr, camera_height_m, focal_px)
            mid = radial_boxes(boxes.xyxy, centre)
            near = np.hypot(mid[:, 0] - centre[0], mid[:, 1] - centre[1]) < self.centre_share * radius
            rotated, conf = np.concatenate([rotated[inner], mid[near]]), np.concatenate([conf[inner], boxes.confidence[near]])
        return rotated, conf

    def _tiles(self, image: NDArray[np.uint8], centre: tuple[float, float], radius: float) -> tuple[FloatArray, FloatArray]:
        lay, n = self.layout, self.input_px
        side = lay.side_share * radius
        k = n / side
        # Shrink the frame once (area-averaged); each tile is then only turned, not shrunk.
        small = cv2.resize(image, None, fx=k, fy=k, interpolation=cv2.INTER_AREA) if k < 1 else image
        k_small = small.shape[1] / image.shape[1]
        c = np.array([(centre[0] + 0.5) * k_small - 0.5, (centre[1] + 0.5) * k_small - 0.5])
        scale = k / k_small  # from the shrunk frame's pixels to the tile's
        found, scores = [], []
        for t in range(lay.tiles):
            theta = 2 * math.pi * t / lay.tiles
            back = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])  # tile → frame turn
            offset = np.array([n / 2, n + lay.start_share * radius * k])  # the centre, below the tile
            m = np.hstack([scale * back.T, (offset - scale * back.T @ c)[:, None]])
            tile = cv2.warpAffine(small, m, (n, n), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            boxes = self.tile_detector.detect_scaled(np.asarray(tile, dtype=np.uint8), 1.0)
            x = boxes.xyxy
            whole = (x[:, 0] > EDGE_PX) & (x[:, 2] < n - 1 - EDGE_PX)
            x, conf = x[whole], boxes.confidence[whole]
            uv = np.column_stack([(x[:, 0] + x[:, 2]) / 2, (x[:, 1] + x[:, 3]) / 2])
            q = (uv - offset) / k  # tile pixels → frame pixels about the centre, turned upright
            p = np.asarray(centre) + q @ back.T
            found.append(np.column_stack([p, (x[:, 2] - x[:, 0]) / k, (x[:, 3] - x[:, 1]) / k, np.full(len(x), math.degrees(theta))]))
            scores.append(conf)
        rotated, conf = np.concatenate(found), np.concatenate(scores)
        keep = rotated_nms(rotated, conf, lay.nms_iou)
        return rotated[keep], conf[keep]


RIM_TILES = "rim-tiles"
"""The name that selects this detector wherever a model is named (site file, ``--model``)."""
TILE_MODEL = Path(__file__).resolve().parent.parent / "data" / "models" / "yolox-nano-coco.onnx"


def load_rim_tiles(threads: int = 2, score_threshold: float = 0.4, tile_model: str | Path | None = None) -> RimTileDetector:
    """The rim-tile detector with the shipped YOLOX-nano (or ``tile_model``) on every tile and
    the shipped general model for the people right under the camera."""
    from bevflow.detect.runtime import Detector  # onnxruntime is imported only when a model loads

    tiles = Detector(tile_model or TILE_MODEL, threads=threads, score_threshold=score_threshold)
    return RimTileDetector(tiles, centre=Detector(None, threads=threads, score_threshold=score_threshold))


def rotated_nms(rotated: FloatArray, scores: FloatArray, iou_threshold: float) -> NDArray[np.int64]:
    """Greedy non-maximum suppression by rotated IoU; the indices kept, best score first. Only
    kept boxes are compared with the rest, so the cost follows the people, not the candidates."""
    order = np.argsort(-np.asarray(scores), kind="stable")
    boxes = np.asarray(rotated, np.float64).reshape(-1, 5)[order]
    alive = np.ones(len(order), dtype=bool)
    keep = []
    for i in range(len(order)):
        if not alive[i]:
            continue
        keep.append(order[i])
        rest = np.nonzero(alive[i + 1 :])[0] + i + 1
        if len(rest):
            alive[rest] &= rotated_iou_matrix(boxes[i], boxes[rest])[0] <= iou_threshold
    return np.asarray(keep, dtype=np.int64)
