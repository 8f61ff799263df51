"""Pictures of what the detector did on annotated frames, so a person can see its mistakes.

Each frame is written with the truth in green, the detections kept at the scoring's best-F1
threshold in yellow where they match a person (rotated IoU ≥ 0.5, as ``AP50_rotated`` counts) and
red where they match nobody, each with its score; a cross marks the image circle's centre that
radial angles were taken about. On a frame nobody annotated there is nothing to judge by: its
detections are drawn in blue.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.rotated import rotated_corners, rotated_iou_matrix
from bevflow.evaluation.detector import FrameResult, match_by_iou, read_image

TRUTH = (80, 220, 80)
HIT = (0, 220, 255)
MISS = (40, 40, 255)
UNJUDGED = (255, 160, 40)


def draw_frame(image: NDArray[np.uint8], result: FrameResult, threshold: float) -> NDArray[np.uint8]:
    """A copy of ``image`` with ``result``'s truth and its detections scoring ≥ ``threshold``."""
    out = image.copy()
    line = max(2, round(max(image.shape[:2]) / 500))
    keep = result.confidence >= threshold
    dets, conf = result.detections_rotated[keep], result.confidence[keep]
    hits = match_by_iou(rotated_iou_matrix(dets, result.truth_rotated), conf)
    _polygons(out, result.truth_rotated, TRUTH, line)
    for box, score, hit in zip(dets, conf, hits, strict=True):
        colour = (HIT if hit else MISS) if result.entry.annotated else UNJUDGED
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
    """Draw every frame into ``folder`` as ``<image name>.jpg``; returns the files written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for r in results:
        path = folder / f"{r.entry.path.stem}.jpg"
        if not cv2.imwrite(str(path), draw_frame(read_image(r.entry.path), r, threshold)):
            raise OSError(f"cannot write {path}")
        written.append(path)
    return written
