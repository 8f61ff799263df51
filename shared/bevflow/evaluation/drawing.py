"""Pictures of what the detector did on annotated frames, so a person can see its mistakes.

Each frame is written with the truth in green, the detections kept at the scoring's best-F1
threshold in yellow where they match a person (rotated IoU ≥ 0.5, as ``AP50_rotated`` counts) and
red where they match nobody, each with its score; a crowd region (``iscrowd``) and the detections
it makes count for nothing are grey; a cross marks the image circle's centre that radial angles
were taken about. On a frame nobody annotated there is nothing to judge by: its
detections are drawn in blue.

Each drawing is named after its image's path below the images' common folder, so frames of one
name in different folders (``cam1/0001.jpg``, ``cam2/0001.jpg``) or of one stem in one folder
(``a.jpg``, ``a.png``) never overwrite each other (``drawing_names``).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.rotated import rotated_corners, rotated_iou_matrix
from bevflow.evaluation.detector import FrameResult, in_crowd, match_by_iou, read_image

TRUTH = (80, 220, 80)
HIT = (0, 220, 255)
MISS = (40, 40, 255)
UNJUDGED = (255, 160, 40)
IGNORED = (160, 160, 160)


def draw_frame(image: NDArray[np.uint8], result: FrameResult, threshold: float) -> NDArray[np.uint8]:
    """A copy of ``image`` with ``result``'s truth and its detections scoring ≥ ``threshold``."""
    out = image.copy()
    line = max(2, round(max(image.shape[:2]) / 500))
    keep = result.confidence >= threshold
    dets, conf = result.detections_rotated[keep], result.confidence[keep]
    hits = match_by_iou(rotated_iou_matrix(dets, result.truth_rotated), conf)
    crowded = in_crowd(result.xyxy[keep], result.crowd_xyxy)
    _polygons(out, result.truth_rotated, TRUTH, line)
    _polygons(out, result.entry.crowd, IGNORED, line)
    for box, score, hit, ignored in zip(dets, conf, hits, crowded, strict=True):
        colour = (HIT if hit else IGNORED if ignored else MISS) if result.entry.annotated else UNJUDGED
        _polygons(out, box[None], colour, line)
        corner = rotated_corners(box[None])[0].min(axis=0)
        cv2.putText(out, f"{score:.2f}", (int(corner[0]), int(corner[1]) - 2), cv2.FONT_HERSHEY_SIMPLEX, 0.35 * line, colour, line)
    cx, cy = result.setup.centre
    cv2.drawMarker(out, (round(cx), round(cy)), (255, 255, 255), cv2.MARKER_CROSS, 12 * line, line)
    return out


def _polygons(image: NDArray[np.uint8], rotated: NDArray[np.float64], colour: tuple[int, int, int], line: int) -> None:
    corners = np.round(rotated_corners(rotated)).astype(np.int32)
    cv2.polylines(image, list(corners), True, colour, line, cv2.LINE_AA)


def write_drawings(results: Sequence[FrameResult], folder: Path, threshold: float) -> list[Path]:
    """Draw every frame into ``folder``, each under its own name (``drawing_names``); returns the
    files written."""
    written = [Path(folder) / name for name in drawing_names([r.entry.path for r in results])]
    for r, path in zip(results, written, strict=True):
        path.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(path), draw_frame(read_image(r.entry.path), r, threshold)):
            raise OSError(f"cannot write {path}")
    return written


def drawing_names(images: Sequence[Path]) -> list[Path]:
    """Where each image's drawing goes, relative to the drawings' folder: the image's path below
    the images' common folder as a JPEG (``cam1/0001.png`` → ``cam1/0001.jpg``); where two images
    would share that name (``a.jpg`` and ``a.png``), each keeps its own suffix (``a.jpg.jpg``,
    ``a.png.jpg``)."""
    paths = [Path(os.path.abspath(p)) for p in images]  # not resolved: a linked frame keeps the link's name
    if not paths:
        return []
    below = [p.relative_to(os.path.commonpath([q.parent for q in paths])) for p in paths]
    plain = [p.with_suffix(".jpg") for p in below]
    shared = Counter(plain)
    return [name if shared[name] == 1 else p.with_name(p.name + ".jpg") for name, p in zip(plain, below, strict=True)]
