"""Detection accuracy on the floor of an annotated multi-camera dataset, end to end.

For every frame: each camera's annotated boxes go through the detector-noise model
(``bevflow.sim.noise``), each noisy box becomes a cylinder (``bevflow.cylinder``, by the chosen
projection method), the cameras' cylinders are fused (``bevflow.fusion``), and the fused feet
inside the dataset's annotated area are scored against the ground truth
(``bevflow.metrics.detection``, matched within ``threshold_m``, 0.5 m by default as in
WILDTRACK's own evaluation).

Annotation boxes may reach past the image border (WILDTRACK's do, 3,167 of the 19,824 public
ones: they bound the whole person), which no detector can report. ``clip_to_image=True`` clips
every noisy box to the image, as a detector's would be, and drops boxes left with no area; it is
off by default so the boxes are the dataset's own.

Estimates outside the annotated area that match nobody are dropped before scoring (after fusion,
so the area does not change what merges): nobody outside it is annotated, so they are neither
right nor wrong. An estimate just outside that matches a person just inside (within
``threshold_m``) is kept and counts as found: a person 0.1 m inside the edge placed 0.2 m outside
it has been found, and dropping the estimate would score them as missed (``scored_estimates``).
Each camera is also scored alone (its own cylinders in the area against the people it sees, weak
fits left out as fusion leaves them out when alone), which separates a camera's calibration or
projection error from what fusion does.

Fusion is ``bevflow.fusion``'s default, uncertainty-aware one; ``position_noise=None`` runs the
paper's plain distance rule instead, and ``grid`` sets the cylinder fit, for ablations.

The random noise of frame f, camera i is drawn from ``view_rng(seed, f, i)``: a run over a slice
of the frames sees exactly the noise those frames get in a full run, and every method sees the
same noisy boxes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol, TypedDict

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera
from bevflow.cylinder import CylinderGrid, ProjectionMethod, fit_cylinders
from bevflow.detections import Boxes, Cylinders
from bevflow.fusion import PositionNoise, fuse_cylinders
from bevflow.metrics.detection import DetectionScores, score_detections
from bevflow.metrics.matching import match_positions
from bevflow.sim.noise import DetectorNoise, NoisyBoxes, apply_detector_noise, view_rng
from bevflow.stature import with_stature

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class AnnotatedView(Protocol):
    """One camera's boxes in one frame and whose they are. A view may also carry ``visible_xyxy``
    (N, 4), the visible extent of each box, which the noise model then uses for truncation.
    The protocols here are read-only: datasets are frozen."""

    @property
    def boxes(self) -> Boxes: ...
    @property
    def person_ids(self) -> IntArray: ...


class AnnotatedFrame(Protocol):
    @property
    def frame(self) -> int: ...
    @property
    def person_ids(self) -> IntArray: ...
    @property
    def feet_xy(self) -> FloatArray: ...
    @property
    def views(self) -> Sequence[AnnotatedView]: ...


class Area(Protocol):
    def contains(self, xy: FloatArray) -> NDArray[np.bool_]: ...


class AnnotatedDataset(Protocol):
    """What an evaluation needs; ``bevflow.datasets.wildtrack.WildtrackDataset`` is one."""

    @property
    def camera_ids(self) -> Sequence[str]: ...
    @property
    def cameras(self) -> Sequence[Camera]: ...
    @property
    def frames(self) -> Sequence[AnnotatedFrame]: ...
    @property
    def area(self) -> Area: ...


@dataclass(frozen=True)
class CameraCounts:
    """What happened to one camera's boxes over the evaluated frames."""

    camera_id: str
    boxes: int  # annotated boxes (people the camera sees)
    detections: int  # boxes after the noise model
    dropped: int
    truncated: int
    false_positives: int
    clipped: int  # boxes cut by the image border (only with clip_to_image)
    duplicates: int  # detections left out as another's of one person (Boxes.distinct), as a detector suppresses them
    unplaced: int  # detections the projection could not put on the floor
    weak: int  # placed, but weak (a cut box on a camera that cannot rebuild it): never a person alone
    outside_area: int  # placed, but outside the annotated area
    alone: DetectionScores  # this camera's cylinders in the area against the people it sees

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["alone"] = self.alone.as_dict()
        return out



def _camera_counts(camera_id: str, counts: NDArray[np.int64], alone: DetectionScores) -> CameraCounts:
    """``counts``: the CameraCounts fields from boxes to outside_area, in order."""
    boxes, detections, dropped, truncated, false_positives, clipped, duplicates, unplaced, weak, outside_area = counts.tolist()
    return CameraCounts(
        camera_id, boxes, detections, dropped, truncated, false_positives, clipped, duplicates, unplaced, weak, outside_area, alone
    )

@dataclass(frozen=True)
class DetectionEvaluation:
    """Fused detection scores of one projection method over a run, and per-camera counts."""

    method: str
    noise: DetectorNoise
    seed: int
    threshold_m: float
    fusion_distance_m: float
    position_noise: PositionNoise | None  # None: the paper's plain distance rule
    clip_to_image: bool
    frame_numbers: tuple[int, ...]
    scores: DetectionScores
    views_per_estimate: float  # mean number of cameras merged into a scored fused estimate
    per_camera: tuple[CameraCounts, ...]
    fused: tuple[Cylinders, ...] = field(default=(), repr=False, compare=False)
    """Every evaluated frame's fused cylinders, all of them (inside the area or not): what a
    tracker downstream consumes."""
    sightings: tuple[Cylinders, ...] = field(default=(), repr=False, compare=False)
    """Every evaluated frame's ``Fusion.sightings`` (weak views that placed nobody)."""

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready; the headline numbers (MODA, MODP, precision, recall, F1, APE, method,
        frames) are top-level keys."""
        s = self.scores
        return {
            "method": self.method,
            "frames": len(self.frame_numbers),
            "MODA": s.MODA,
            "MODP": s.MODP,
            "precision": s.precision,
            "recall": s.recall,
            "F1": s.F1,
            "APE": s.APE,
            "tp": s.tp,
            "fp": s.fp,
            "fn": s.fn,
            "n_gt": s.n_gt,
            "views_per_estimate": self.views_per_estimate,
            "first_frame": self.frame_numbers[0] if self.frame_numbers else None,
            "last_frame": self.frame_numbers[-1] if self.frame_numbers else None,
            "noise": asdict(self.noise),
            "seed": self.seed,
            "threshold_m": self.threshold_m,
            "fusion_distance_m": self.fusion_distance_m,
            "fusion": "paper" if self.position_noise is None else {"position_noise": asdict(self.position_noise)},
            "clip_to_image": self.clip_to_image,
            "per_camera": [c.as_dict() for c in self.per_camera],
        }


def noisy_detections(dataset: AnnotatedDataset, frame: AnnotatedFrame, noise: DetectorNoise, seed: int) -> list[NoisyBoxes]:
    """The noise model applied to every camera's boxes of one frame."""
    return [
        apply_detector_noise(
            view.boxes,
            noise,
            view_rng(seed, int(frame.frame), i),
            camera.image_size,
            visible=getattr(view, "visible_xyxy", None),
        )
        for i, (camera, view) in enumerate(zip(dataset.cameras, frame.views, strict=True))
    ]


def clip_boxes_to_image(noisy: NoisyBoxes, image_size: tuple[int, int]) -> tuple[NoisyBoxes, int]:
    """Boxes clipped to the image [0, w] x [0, h]; those left with no area are removed. Also
    returns how many boxes the border changed (removed ones included)."""
    w, h = image_size
    xyxy = noisy.boxes.xyxy.copy()
    xyxy[:, [0, 2]] = xyxy[:, [0, 2]].clip(0.0, w)
    xyxy[:, [1, 3]] = xyxy[:, [1, 3]].clip(0.0, h)
    changed = int(np.any(xyxy != noisy.boxes.xyxy, axis=1).sum())
    keep = (xyxy[:, 2] > xyxy[:, 0]) & (xyxy[:, 3] > xyxy[:, 1])
    boxes = Boxes(xyxy=xyxy[keep], confidence=noisy.boxes.confidence[keep])
    return NoisyBoxes(boxes=boxes, source=noisy.source[keep], truncated=noisy.truncated[keep]), changed


def scored_estimates(area: Area, gt_xy: FloatArray, est_xy: FloatArray, threshold_m: float) -> NDArray[np.bool_]:
    """(N,) which estimates of one frame are scored: those inside ``area`` and those outside it
    that a one-to-one match of every estimate with the ground truth pairs with a person. Scoring
    just these finds exactly as many people as scoring all estimates would, without counting
    the unannotated surroundings as false positives."""
    keep = area.contains(est_xy)
    if len(gt_xy) and not keep.all():
        _, matched, _ = match_positions(gt_xy, est_xy, threshold_m)
        keep[matched] = True
    return keep


class DetectionOptions(TypedDict, total=False):
    """``evaluate_detection``'s settings after the dataset, for callers that pass them on."""

    method: ProjectionMethod
    noise: DetectorNoise
    seed: int
    frames: slice
    threshold_m: float
    fusion_distance_m: float
    clip_to_image: bool
    position_noise: PositionNoise | None
    grid: CylinderGrid


def evaluate_detection(
    dataset: AnnotatedDataset,
    method: ProjectionMethod = "cylinder",
    noise: DetectorNoise = DetectorNoise(),
    seed: int = 0,
    frames: slice = slice(None),
    threshold_m: float = 0.5,
    fusion_distance_m: float = 0.45,
    clip_to_image: bool = False,
    position_noise: PositionNoise | None = PositionNoise(),
    grid: CylinderGrid = CylinderGrid(),
) -> DetectionEvaluation:
    """Run noise -> projection -> fusion on ``dataset.frames[frames]`` and score the fused feet."""
    selected = list(dataset.frames[frames])
    cameras = list(dataset.cameras)
    n_cam = len(cameras)
    gt: list[FloatArray] = []
    fused_xy: list[FloatArray] = []
    views_merged: list[FloatArray] = []
    fused_frames: list[Cylinders] = []
    sightings: list[Cylinders] = []
    alone_gt: list[list[FloatArray]] = [[] for _ in cameras]
    alone_est: list[list[FloatArray]] = [[] for _ in cameras]
    counts = np.zeros((n_cam, 10), dtype=np.int64)  # the CameraCounts fields from boxes to outside_area
    for frame in selected:
        per_camera = []
        for i, (camera, view, noisy) in enumerate(zip(cameras, frame.views, noisy_detections(dataset, frame, noise, seed), strict=True)):
            clipped = 0
            if clip_to_image:
                noisy, clipped = clip_boxes_to_image(noisy, camera.image_size)
            boxes = noisy.boxes.distinct()
            cylinders = fit_cylinders(camera, boxes, method=method, grid=grid).with_camera(i)
            cylinders = with_stature(camera, boxes, cylinders, method)
            placed: NDArray[np.bool_] = np.all(np.isfinite(cylinders.xy), axis=1)
            weak = placed & (cylinders.score <= 0)
            inside = dataset.area.contains(cylinders.xy)
            counts[i] += [
                len(view.boxes),
                len(noisy.boxes),
                len(view.boxes) - int((noisy.source >= 0).sum()),
                int(noisy.truncated.sum()),
                int((noisy.source < 0).sum()),
                clipped,
                len(noisy.boxes) - len(boxes),
                int((~placed).sum()),
                int(weak.sum()),
                int((placed & ~inside).sum()),
            ]
            seen = np.isin(frame.person_ids, view.person_ids)
            alone_gt[i].append(frame.feet_xy[seen])
            strong_xy = cylinders.xy[placed & ~weak]
            alone_est[i].append(strong_xy[scored_estimates(dataset.area, frame.feet_xy[seen], strong_xy, threshold_m)])
            per_camera.append(cylinders[placed])
        fusion = fuse_cylinders(Cylinders.merge(per_camera), cameras, distance_m=fusion_distance_m, noise=position_noise)
        scored = scored_estimates(dataset.area, frame.feet_xy, fusion.fused.xy, threshold_m)
        gt.append(frame.feet_xy)
        fused_xy.append(fusion.fused.xy[scored])
        views_merged.append(np.asarray(fusion.n_views, dtype=np.float64)[scored])
        fused_frames.append(fusion.fused)
        sightings.append(fusion.sightings)
    merged = np.concatenate(views_merged) if views_merged else np.zeros(0)
    return DetectionEvaluation(
        method=method,
        noise=noise,
        seed=seed,
        threshold_m=threshold_m,
        fusion_distance_m=fusion_distance_m,
        position_noise=position_noise,
        clip_to_image=clip_to_image,
        frame_numbers=tuple(int(f.frame) for f in selected),
        scores=score_detections(gt, fused_xy, threshold_m=threshold_m),
        views_per_estimate=float(merged.mean()) if len(merged) else float("nan"),
        per_camera=tuple(
            _camera_counts(
                str(dataset.camera_ids[i]),
                counts[i],
                score_detections(alone_gt[i], alone_est[i], threshold_m=threshold_m),
            )
            for i in range(n_cam)
        ),
        fused=tuple(fused_frames),
        sightings=tuple(sightings),
    )
