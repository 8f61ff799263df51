"""How well a person detector finds people in annotated images: AP50, and precision, recall and
F1 at the score threshold that maximises F1.

Matching follows COCO/VOC: in each image, detections are taken best score first and each is
matched to the unmatched ground-truth box it overlaps most, if their IoU is at least 0.5; the
rest are false positives. AP is the area under the precision–recall curve with precision made
monotone (all-point interpolation, as VOC since 2010 and COCO do). Rotated ground-truth boxes
count as their enclosing axis-aligned rectangles (``bevflow.detect.coco``), as the detector's
boxes are axis-aligned.

>>> gt = [np.array([[0.0, 0.0, 10.0, 10.0]])]
>>> s = score_boxes([np.array([[1.0, 0.0, 10.0, 10.0], [50.0, 50.0, 60.0, 60.0]])], [np.array([0.9, 0.3])], gt)
>>> round(s.AP50, 3), round(s.precision, 3), round(s.recall, 3), round(s.F1, 3)
(1.0, 1.0, 1.0, 1.0)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.coco import CocoImage, read_coco
from bevflow.detections import Boxes

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DetectorScores:
    """AP50 over all scores; precision, recall and F1 at ``threshold`` (the best-F1 score cut);
    counts of images, annotations (ground-truth boxes) and detections."""

    AP50: float
    precision: float
    recall: float
    F1: float
    threshold: float
    images: int
    annotations: int
    detections: int

    def as_dict(self) -> dict:
        return asdict(self)


def iou_matrix(a: FloatArray, b: FloatArray) -> FloatArray:
    """(P, 4) × (Q, 4) xyxy → (P, Q) intersection over union."""
    a, b = np.asarray(a, np.float64).reshape(-1, 4), np.asarray(b, np.float64).reshape(-1, 4)
    w = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    h = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = w * h
    area = lambda x: np.clip(x[:, 2] - x[:, 0], 0, None) * np.clip(x[:, 3] - x[:, 1], 0, None)  # noqa: E731
    return inter / np.maximum(area(a)[:, None] + area(b)[None, :] - inter, 1e-12)


def match_image(xyxy: FloatArray, scores: FloatArray, truth: FloatArray, iou_threshold: float = 0.5) -> NDArray[np.bool_]:
    """Whether each detection (in the given order) is a true positive, greedy by score."""
    order = np.argsort(-np.asarray(scores), kind="stable")
    tp = np.zeros(len(order), dtype=bool)
    if not len(truth) or not len(order):
        return tp
    iou = iou_matrix(np.asarray(xyxy)[order], truth)
    free = np.ones(len(truth), dtype=bool)
    for k in range(len(order)):
        cand = np.where(free, iou[k], -1.0)
        j = int(cand.argmax())
        if cand[j] >= iou_threshold:
            free[j] = False
            tp[order[k]] = True
    return tp


def score_boxes(
    detections: Sequence[FloatArray], scores: Sequence[FloatArray], truth: Sequence[FloatArray], iou_threshold: float = 0.5
) -> DetectorScores:
    """Score per-image detections (xyxy, scores) against per-image ground truth (xyxy)."""
    if not (len(detections) == len(scores) == len(truth)):
        raise ValueError("detections, scores and truth need one entry per image")
    all_scores, all_tp = [], []
    for d, s, t in zip(detections, scores, truth, strict=True):
        all_tp.append(match_image(d, s, np.asarray(t, np.float64).reshape(-1, 4), iou_threshold))
        all_scores.append(np.asarray(s, np.float64).reshape(-1))
    s = np.concatenate(all_scores) if all_scores else np.zeros(0)
    tp = np.concatenate(all_tp) if all_tp else np.zeros(0, bool)
    n_truth = int(sum(len(np.asarray(t).reshape(-1, 4)) for t in truth))
    order = np.argsort(-s, kind="stable")
    s, tp = s[order], tp[order]
    ctp, cfp = np.cumsum(tp), np.cumsum(~tp)
    recall = ctp / max(n_truth, 1)
    precision = ctp / np.maximum(ctp + cfp, 1)
    # Cut only between different scores: detections with equal scores stand or fall together.
    last = np.r_[s[1:] != s[:-1], True] if len(s) else np.zeros(0, bool)
    f1 = np.where(last, 2 * precision * recall / np.maximum(precision + recall, 1e-12), -1.0)
    if len(s) and n_truth and f1.max() > 0:
        best = int(f1.argmax())
        p, r, f, thr = float(precision[best]), float(recall[best]), float(f1[best]), float(s[best])
    else:
        p, r, f, thr = 0.0, 0.0, 0.0, 1.0
    envelope = np.maximum.accumulate(np.r_[precision, 0.0][::-1])[::-1]
    ap = float(np.sum(np.diff(np.r_[0.0, recall]) * envelope[:-1][: len(recall)])) if n_truth else 0.0
    return DetectorScores(AP50=ap, precision=p, recall=r, F1=f, threshold=thr, images=len(truth), annotations=n_truth, detections=len(s))


class ImageDetector:
    """What ``evaluate_detector`` needs (``bevflow.detect.runtime.Detector`` is one)."""

    def detect(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float) -> Boxes: ...

    def detect_scaled(self, image_bgr: NDArray[np.uint8], scale: float = 1.0) -> Boxes: ...


def evaluate_detector(
    detector: ImageDetector,
    annotations: Path,
    images_dir: Path | None = None,
    camera_height_m: float | None = None,
    focal_px: float | None = None,
    scale: float = 1.0,
    progress: Callable[[int, int], None] | None = None,
) -> DetectorScores:
    """Run ``detector`` on every image of a COCO file and score it. Each image is scaled from its
    own ``camera_height_m`` / ``focal_px`` (COCO image keys) when present, else from the ones given
    here, else resized by ``scale``. Raises FileNotFoundError / ValueError for unreadable input."""
    entries: list[CocoImage] = read_coco(annotations, images_dir)
    dets, scores, truth = [], [], []
    for k, entry in enumerate(entries):
        image = cv2.imread(str(entry.path), cv2.IMREAD_COLOR)
        if image is None:
            raise FileNotFoundError(f"cannot read image {entry.path}")
        h = entry.camera_height_m if entry.camera_height_m is not None else camera_height_m
        f = entry.focal_px if entry.focal_px is not None else focal_px
        boxes = detector.detect(image, h, f) if h is not None and f is not None else detector.detect_scaled(image, scale)
        dets.append(boxes.xyxy)
        scores.append(boxes.confidence)
        truth.append(entry.xyxy)
        if progress is not None:
            progress(k + 1, len(entries))
    return score_boxes(dets, scores, truth)
