"""How well a person detector finds people in annotated images: AP50, and precision, recall and
F1 at the score threshold that maximises F1.

Matching follows COCO/VOC: in each image, detections are taken best score first and each is
matched to the unmatched ground-truth box it overlaps most, if their IoU is at least 0.5; the
rest are false positives. AP is the area under the precision–recall curve with precision made
monotone (all-point interpolation, as VOC since 2010 and COCO do). A rotated ground-truth box
counts for AP50 as the upright box of the person lying in it, the outline of the ellipse inside
it (``bevflow.detect.rotated.outline_xyxy``): the box the rim tiles give the pipeline for the
same rotated box, and about what an annotator drawing upright boxes would draw.

``AP50_rotated`` scores as CEPDOF, WEPDTOF and RAPiD do: IoU between rotated boxes
(``bevflow.detect.rotated``), truth as annotated. A detection without an angle is turned to its
radial angle about the image circle's centre, sized so that its enclosing box is the detection.
For annotation files without angles both sides stay axis-aligned and it equals AP50.

Crowd regions (COCO's ``iscrowd`` 1, ``bevflow.detect.coco``) are scored as COCO does: they are not
people to find, and a detection that matches nobody but lies mostly inside one (at least half its
area, against the region's enclosing upright box) counts neither for nor against the detector.

>>> gt = [np.array([[0.0, 0.0, 10.0, 10.0]])]
>>> s = score_boxes([np.array([[1.0, 0.0, 10.0, 10.0], [50.0, 50.0, 60.0, 60.0]])], [np.array([0.9, 0.3])], gt)
>>> round(s.AP50, 3), round(s.precision, 3), round(s.recall, 3), round(s.F1, 3)
(1.0, 1.0, 1.0, 1.0)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.circle import AssumedCalibration, assume_calibration
from bevflow.detect.coco import CocoImage, read_coco, unannotated_images
from bevflow.detect.rotated import outline_xyxy, radial_boxes, rotated_iou_matrix
from bevflow.detections import Boxes
from bevflow.evaluation.turned import turned

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DetectorScores:
    """AP50 over all scores, between axis-aligned boxes and between rotated ones
    (``AP50_rotated``); precision, recall and F1 at ``threshold`` (the best-F1 score cut, axis-
    aligned); counts of images, annotations (ground-truth boxes) and detections; the detector's
    mean time per frame when it was timed."""

    AP50: float
    AP50_rotated: float
    precision: float
    recall: float
    F1: float
    threshold: float
    images: int
    annotations: int
    detections: int
    ms_per_frame: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def iou_matrix(a: FloatArray, b: FloatArray) -> FloatArray:
    """(P, 4) × (Q, 4) xyxy → (P, Q) intersection over union."""
    a, b = np.asarray(a, np.float64).reshape(-1, 4), np.asarray(b, np.float64).reshape(-1, 4)
    inter = _intersection(a, b)
    iou: FloatArray = inter / np.maximum(_area(a)[:, None] + _area(b)[None, :] - inter, 1e-12)
    return iou


def _intersection(a: FloatArray, b: FloatArray) -> FloatArray:
    """(P, 4) × (Q, 4) xyxy → (P, Q) areas of overlap."""
    w = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    h = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter: FloatArray = w * h
    return inter


def _area(xyxy: FloatArray) -> FloatArray:
    area: FloatArray = np.clip(xyxy[:, 2] - xyxy[:, 0], 0, None) * np.clip(xyxy[:, 3] - xyxy[:, 1], 0, None)
    return area


def match_by_iou(iou: FloatArray, scores: FloatArray, iou_threshold: float = 0.5) -> NDArray[np.bool_]:
    """Whether each detection (row of ``iou``, in the given order) is a true positive: greedy by
    score, each to the free ground-truth box (column) it overlaps most."""
    order = np.argsort(-np.asarray(scores), kind="stable")
    tp = np.zeros(len(order), dtype=bool)
    if not iou.size:
        return tp
    iou = iou[order]
    free = np.ones(iou.shape[1], dtype=bool)
    for k in range(len(order)):
        cand = np.where(free, iou[k], -1.0)
        j = int(cand.argmax())
        if cand[j] >= iou_threshold:
            free[j] = False
            tp[order[k]] = True
    return tp


def in_crowd(xyxy: FloatArray, crowd: FloatArray, share: float = 0.5) -> NDArray[np.bool_]:
    """Whether each detection (P, 4) lies at least ``share`` of its area inside one of the crowd
    regions (M, 4), as COCO judges detections against ``iscrowd`` regions."""
    a, b = np.asarray(xyxy, np.float64).reshape(-1, 4), np.asarray(crowd, np.float64).reshape(-1, 4)
    if not len(a) or not len(b):
        return np.zeros(len(a), dtype=bool)
    inside: NDArray[np.bool_] = (_intersection(a, b) / np.maximum(_area(a), 1e-12)[:, None]).max(axis=1) >= share
    return inside


def match_image(xyxy: FloatArray, scores: FloatArray, truth: FloatArray, iou_threshold: float = 0.5) -> NDArray[np.bool_]:
    """Whether each detection (in the given order) is a true positive, greedy by score."""
    return match_by_iou(iou_matrix(xyxy, truth), scores, iou_threshold)


@dataclass(frozen=True)
class _Curve:
    AP: float
    precision: float
    recall: float
    F1: float
    threshold: float


def _curve(tp: list[NDArray[np.bool_]], scores: Sequence[FloatArray], n_truth: int) -> _Curve:
    """AP (all-point interpolation) and the best-F1 operating point of pooled per-image matches."""
    s = np.concatenate([np.asarray(x, np.float64).reshape(-1) for x in scores]) if len(scores) else np.zeros(0)
    hit = np.concatenate(tp) if tp else np.zeros(0, bool)
    order = np.argsort(-s, kind="stable")
    s, hit = s[order], hit[order]
    ctp, cfp = np.cumsum(hit), np.cumsum(~hit)
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
    return _Curve(ap, p, r, f, thr)


def score_boxes(
    detections: Sequence[FloatArray],
    scores: Sequence[FloatArray],
    truth: Sequence[FloatArray],
    iou_threshold: float = 0.5,
    rotated_detections: Sequence[FloatArray] | None = None,
    rotated_truth: Sequence[FloatArray] | None = None,
    crowd: Sequence[FloatArray] | None = None,
) -> DetectorScores:
    """Score per-image detections (xyxy, scores) against per-image ground truth (xyxy). With
    ``rotated_detections`` and ``rotated_truth`` ((N, 5) per image, ``bevflow.detect.rotated``)
    ``AP50_rotated`` matches those instead; without them it is the axis-aligned AP50. ``crowd``:
    each image's crowd regions (xyxy), where unmatched detections are ignored (module docstring)."""
    if not (len(detections) == len(scores) == len(truth)):
        raise ValueError("detections, scores and truth need one entry per image")
    truth = [np.asarray(t, np.float64).reshape(-1, 4) for t in truth]
    n_truth = int(sum(len(t) for t in truth))
    crowded = [in_crowd(d, c) for d, c in zip(detections, crowd or [np.zeros((0, 4))] * len(truth), strict=True)]
    hits = [match_image(d, s, t, iou_threshold) for d, s, t in zip(detections, scores, truth, strict=True)]
    aligned = _curve(*_judged(hits, scores, crowded), n_truth)
    rotated_ap = aligned.AP
    if rotated_detections is not None and rotated_truth is not None:
        if not (len(rotated_detections) == len(rotated_truth) == len(scores)):
            raise ValueError("rotated detections and truth need one entry per image")
        hits = [match_by_iou(rotated_iou_matrix(d, t), s, iou_threshold) for d, s, t in zip(rotated_detections, scores, rotated_truth, strict=True)]
        rotated_ap = _curve(*_judged(hits, scores, crowded), n_truth).AP
    n_det = int(sum(np.asarray(s).size for s in scores))
    return DetectorScores(AP50=aligned.AP, AP50_rotated=rotated_ap, precision=aligned.precision, recall=aligned.recall,
                          F1=aligned.F1, threshold=aligned.threshold, images=len(truth), annotations=n_truth, detections=n_det)  # fmt: skip


def _judged(hits: list[NDArray[np.bool_]], scores: Sequence[FloatArray],
            crowded: list[NDArray[np.bool_]]) -> tuple[list[NDArray[np.bool_]], list[FloatArray]]:  # fmt: skip
    """Each image's hits and scores less the detections that matched nobody inside a crowd region."""
    kept = [h | ~c for h, c in zip(hits, crowded, strict=True)]
    return [h[k] for h, k in zip(hits, kept, strict=True)], [np.asarray(s).reshape(-1)[k] for s, k in zip(scores, kept, strict=True)]


class ImageDetector(Protocol):
    """What ``evaluate_detector`` needs (``bevflow.detect.runtime.Detector`` is one). A
    ``RotationAwareDetector`` gives each box's angle; the others' boxes are turned to their radial
    angle about the image circle's centre for ``AP50_rotated``. Frames given a plain scale need a
    ``ScaledDetector``."""

    def detect(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float) -> Boxes: ...


@runtime_checkable
class RotationAwareDetector(Protocol):
    """A detector that knows each box's angle (the rim tiles, ``DetectorBank``): the pipeline's
    boxes and the same people's rotated boxes (N, 5), about ``centre``, the image circle's."""

    def detect_boxes(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
                     centre: tuple[float, float]) -> tuple[Boxes, FloatArray]: ...  # fmt: skip


@runtime_checkable
class ScaledDetector(Protocol):
    """A detector that can also take a frame already resized by a known factor."""

    def detect_scaled(self, image_bgr: NDArray[np.uint8], scale: float = 1.0) -> Boxes: ...


@dataclass(frozen=True)
class FrameSetup:
    """How one frame is fed to the detector: its camera height and focal length (from the
    annotations, the caller, or assumed: ``assumed`` then says what), or a plain ``scale``; and
    the centre its people lie radially about."""

    centre: tuple[float, float]
    camera_height_m: float | None = None
    focal_px: float | None = None
    scale: float | None = None
    assumed: AssumedCalibration | None = None


def frame_setup(entry: CocoImage, image: NDArray[np.uint8], camera_height_m: float | None, focal_px: float | None,
                scale: float | None) -> FrameSetup:  # fmt: skip
    """The image's own keys first, then the caller's height and focal length, then the caller's
    ``scale``; with none of them, what ``bevflow.detect.circle`` assumes of the frame."""
    h = entry.camera_height_m if entry.camera_height_m is not None else camera_height_m
    f = entry.focal_px if entry.focal_px is not None else focal_px
    centre = ((image.shape[1] - 1) / 2, (image.shape[0] - 1) / 2)
    if h is not None and f is not None:
        return FrameSetup(centre, h, f)
    if scale is not None:
        return FrameSetup(centre, scale=scale)
    assumed = assume_calibration(image)
    return FrameSetup((assumed.circle.cx, assumed.circle.cy), assumed.camera_height_m, assumed.focal_px, assumed=assumed)


def run_on_frame(detector: ImageDetector, image: NDArray[np.uint8], setup: FrameSetup) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(xyxy (N, 4), rotated (N, 5), confidence (N,)) of one frame."""
    if setup.scale is not None:
        if not isinstance(detector, ScaledDetector):
            raise ValueError("this detector needs each frame's camera height and focal length, not a scale")
        boxes = detector.detect_scaled(image, setup.scale)
    elif setup.camera_height_m is None or setup.focal_px is None:
        raise ValueError("a frame needs either a scale or its camera's height and focal length")
    elif isinstance(detector, RotationAwareDetector):
        boxes, rotated = detector.detect_boxes(image, setup.camera_height_m, setup.focal_px, setup.centre)
        return boxes.xyxy, np.asarray(rotated, np.float64).reshape(-1, 5), boxes.confidence
    else:
        boxes = detector.detect(image, setup.camera_height_m, setup.focal_px)
    return boxes.xyxy, radial_boxes(boxes.xyxy, setup.centre), boxes.confidence


@dataclass(frozen=True)
class FrameResult:
    """One frame's detections and truth, kept for scoring and drawing."""

    entry: CocoImage
    setup: FrameSetup
    xyxy: FloatArray
    rotated: FloatArray
    confidence: FloatArray

    @property
    def truth_xyxy(self) -> FloatArray:
        """The truth as upright boxes: as annotated, or (rotated files) each box's outline."""
        return outline_xyxy(self.entry.rotated) if self.entry.oriented else self.entry.xyxy

    @property
    def truth_rotated(self) -> FloatArray:
        """The truth as rotated boxes: as annotated, or (axis-aligned files) the boxes at 0°,
        compared with the detections' enclosing boxes so ``AP50_rotated`` equals AP50."""
        return self.entry.rotated if self.entry.oriented else _upright(self.entry.xyxy)

    @property
    def crowd_xyxy(self) -> FloatArray:
        """The frame's crowd regions (``iscrowd``) as upright boxes."""
        return self.entry.crowd_xyxy

    @property
    def detections_rotated(self) -> FloatArray:
        """As the detector turned them, unless the truth is upright boxes (then compared as the
        detections' enclosing boxes)."""
        return self.rotated if self.entry.oriented or not self.entry.annotated else _upright(self.xyxy)


def _upright(xyxy: FloatArray) -> FloatArray:
    x = np.asarray(xyxy, np.float64).reshape(-1, 4)
    return np.column_stack([(x[:, 0] + x[:, 2]) / 2, (x[:, 1] + x[:, 3]) / 2, x[:, 2] - x[:, 0], x[:, 3] - x[:, 1], np.zeros(len(x))])


def detect_frames(
    detector: ImageDetector,
    annotations: Path,
    images_dir: Path | None = None,
    camera_height_m: float | None = None,
    focal_px: float | None = None,
    scale: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> tuple[list[FrameResult], float]:
    """Run ``detector`` on every image of a COCO file (set up by ``frame_setup``); also returns
    the mean milliseconds of the detector per frame. ``log`` hears what was assumed of frames
    without calibration. Raises FileNotFoundError / ValueError for unreadable input."""
    [(results, ms)] = detect_turned_frames(detector, annotations, [0.0], images_dir, camera_height_m, focal_px, scale, progress, log)
    return results, ms


def detect_turned_frames(
    detector: ImageDetector,
    annotations: Path | None,
    degrees: Sequence[float],
    images_dir: Path | None = None,
    camera_height_m: float | None = None,
    focal_px: float | None = None,
    scale: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> list[tuple[list[FrameResult], float]]:
    """``detect_frames`` once for each of ``degrees``: every frame and its truth turned by that
    much about the image circle's centre (``bevflow.evaluation.turned``; 0 leaves it as it is).
    Each frame is read and set up once for all of them. Without ``annotations``, every image of
    ``images_dir`` is run, its people not known (``bevflow.detect.coco.unannotated_images``)."""
    if annotations is not None:
        entries = read_coco(annotations, images_dir)
    elif images_dir is not None:
        entries = unannotated_images(images_dir)
    else:
        raise ValueError("give the annotations, the images' folder, or both")
    results: list[list[FrameResult]] = [[] for _ in degrees]
    seconds = [0.0] * len(degrees)
    for k, entry in enumerate(entries):
        image = read_image(entry.path)
        setup = frame_setup(entry, image, camera_height_m, focal_px, scale)
        if setup.assumed is not None and log is not None:
            log(f"{entry.path.name}: no calibration given; assumed {setup.assumed.describe()}")
        for t, turn in enumerate(degrees):
            seen, frame = turned(entry, image, setup.centre, turn) if turn else (entry, image)
            start = time.perf_counter()
            xyxy, rotated, conf = run_on_frame(detector, frame, setup)
            seconds[t] += time.perf_counter() - start
            results[t].append(FrameResult(seen, setup, xyxy, rotated, conf))
        if progress is not None:
            progress(k + 1, len(entries))
    return [(r, 1000.0 * s / max(len(entries), 1)) for r, s in zip(results, seconds, strict=True)]


def read_image(path: Path) -> NDArray[np.uint8]:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(f"cannot read image {path}")
    return np.asarray(image, dtype=np.uint8)


def score_frames(results: Sequence[FrameResult], ms_per_frame: float | None = None) -> DetectorScores:
    scores = score_boxes([r.xyxy for r in results], [r.confidence for r in results], [r.truth_xyxy for r in results],
                         rotated_detections=[r.detections_rotated for r in results],
                         rotated_truth=[r.truth_rotated for r in results], crowd=[r.crowd_xyxy for r in results])  # fmt: skip
    return replace(scores, ms_per_frame=ms_per_frame)


def evaluate_detector(
    detector: ImageDetector,
    annotations: Path,
    images_dir: Path | None = None,
    camera_height_m: float | None = None,
    focal_px: float | None = None,
    scale: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> DetectorScores:
    """Run ``detector`` on every image of a COCO file and score it. Each image is scaled from its
    own ``camera_height_m`` / ``focal_px`` (COCO image keys) when present, else from the ones given
    here, else resized by ``scale``, else from what its image circle suggests (``log`` hears what
    was assumed). Raises FileNotFoundError / ValueError for unreadable input."""
    results, ms = detect_frames(detector, annotations, images_dir, camera_height_m, focal_px, scale, progress, log)
    return score_frames(results, ms)
