"""The columnar types that cross the stages of the pipeline, one per boundary.

- ``Boxes``: one camera's 2D person detections in one frame (pixels).
- ``Cylinders``: people as world cylinders (metres), one camera's or fused over several.

Each holds numpy arrays of equal length, like supervision's ``Detections``: cheap to slice,
concatenate and hand to vectorised code.

>>> b = Boxes(xyxy=np.array([[10.0, 20.0, 50.0, 90.0]]))
>>> len(b), b.confidence.tolist()
(1, [1.0])
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
# What selects rows of a column: one row, a slice, row numbers or a boolean mask.
RowIndex = int | slice | list[int] | NDArray[np.integer[Any]] | NDArray[np.bool_]

_Scalar = TypeVar("_Scalar", bound=np.generic)

# Two boxes of one frame overlapping more than this are one person boxed twice: a detector's own
# suppression (bevflow.detect.runtime), and that of boxes another detector recorded (Boxes.distinct).
SAME_PERSON_IOU = 0.5


def nms(xyxy: FloatArray, scores: FloatArray, iou_threshold: float) -> NDArray[np.int64]:
    """Greedy non-maximum suppression; the indices kept, best score first."""
    xyxy = np.asarray(xyxy, dtype=np.float64).reshape(-1, 4)
    order = np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable")
    area = np.clip(xyxy[:, 2] - xyxy[:, 0], 0, None) * np.clip(xyxy[:, 3] - xyxy[:, 1], 0, None)
    keep = []
    while len(order):
        i, rest = order[0], order[1:]
        keep.append(i)
        w = np.clip(np.minimum(xyxy[i, 2], xyxy[rest, 2]) - np.maximum(xyxy[i, 0], xyxy[rest, 0]), 0, None)
        h = np.clip(np.minimum(xyxy[i, 3], xyxy[rest, 3]) - np.maximum(xyxy[i, 1], xyxy[rest, 1]), 0, None)
        inter = w * h
        iou = inter / np.maximum(area[i] + area[rest] - inter, 1e-12)
        order = rest[iou <= iou_threshold]
    return np.array(keep, dtype=np.int64)


def _column(name: str, value: ArrayLike | None, n: int, default: float, dtype: type[_Scalar]) -> NDArray[_Scalar]:
    if value is None:
        return np.full(n, default, dtype=dtype)
    arr: NDArray[_Scalar] = np.asarray(value, dtype=dtype).reshape(-1)
    if len(arr) != n:
        raise ValueError(f"{name}: column has {len(arr)} rows, expected {n}")
    return arr


def _rows(name: str, value: ArrayLike, width: int) -> FloatArray:
    """An (N, width) float array; an empty input is zero rows and a flat row of ``width`` is one.
    Anything else is refused rather than reshaped into wrong rows."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, width)
    if arr.shape == (width,):
        return arr.reshape(1, width)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (N, {width}), got {arr.shape}")
    return arr


def _covariance(value: ArrayLike, n: int) -> FloatArray:
    covariance = np.asarray(value, dtype=np.float64)
    if covariance.shape != (n, 2, 2):
        raise ValueError(f"covariance must have shape ({n}, 2, 2), got {covariance.shape}")
    return covariance


@dataclass(frozen=True, eq=False, init=False)
class Boxes:
    """Axis-aligned boxes ``xyxy`` (N, 4) = (x0, y0, x1, y1) in pixels, with confidences.

    The paper's detection D is a 4-point rectangle; an axis-aligned box is its common case and
    ``corners()`` gives the 4 points back."""

    xyxy: FloatArray
    confidence: FloatArray

    # Written out rather than generated: the columns accept anything array-like (and None for
    # the default) but always hold checked numpy arrays.
    def __init__(self, xyxy: ArrayLike, confidence: ArrayLike | None = None) -> None:
        rows = _rows("xyxy", xyxy, 4)
        object.__setattr__(self, "xyxy", rows)
        object.__setattr__(self, "confidence", _column("confidence", confidence, len(rows), 1.0, np.float64))

    @classmethod
    def empty(cls) -> Boxes:
        return cls(xyxy=np.zeros((0, 4)))

    def __len__(self) -> int:
        return len(self.xyxy)

    def __getitem__(self, index: RowIndex) -> Boxes:
        return Boxes(xyxy=self.xyxy[index].reshape(-1, 4), confidence=np.atleast_1d(self.confidence[index]))

    @property
    def width(self) -> FloatArray:
        return self.xyxy[:, 2] - self.xyxy[:, 0]

    @property
    def height(self) -> FloatArray:
        return self.xyxy[:, 3] - self.xyxy[:, 1]

    @property
    def center(self) -> FloatArray:
        return (self.xyxy[:, :2] + self.xyxy[:, 2:]) / 2.0

    @staticmethod
    def merge(parts: list[Boxes]) -> Boxes:
        parts = [p for p in parts if len(p)]
        if not parts:
            return Boxes.empty()
        return Boxes(
            xyxy=np.concatenate([p.xyxy for p in parts]), confidence=np.concatenate([p.confidence for p in parts])
        )

    def distinct(self) -> Boxes:
        """These boxes in their order, less each one overlapping a more confident one by more
        than ``SAME_PERSON_IOU``: one person boxed twice, as a detector's own suppression leaves
        them. Boxes from a detector that suppresses less (CMC2's, docs/RESULTS.md) would each put
        a ghost beside their person for the tracker to follow or swap with a neighbour."""
        if len(self) < 2:
            return self
        return self[np.sort(nms(self.xyxy, self.confidence, SAME_PERSON_IOU))]

    def corners(self) -> FloatArray:
        """(N, 4, 2): top-left, top-right, bottom-right, bottom-left."""
        x0, y0, x1, y1 = self.xyxy.T
        return np.stack([np.stack([x0, y0], 1), np.stack([x1, y0], 1), np.stack([x1, y1], 1), np.stack([x0, y1], 1)], 1)


@dataclass(frozen=True, eq=False, init=False)
class Cylinders:
    """People as upright frustum-cylinders in world metres.

    ``xy`` (N, 2) is the feet position on the floor, ``height`` (N,) and ``radius`` (N,) the
    lower radius (the upper one is a fixed fraction of it). ``camera`` (N,) is the index of the
    camera that produced each one (−1 once fused from several), ``score`` (N,) the fit quality in
    [0, 1] (the best IoU for a cylinder fit), and ``occluded`` (N,) marks fits rebuilt from the
    head after a lower-body occlusion.

    ``covariance`` (N, 2, 2), optional: how uncertain each feet position is, in m², when the stage
    that made the cylinders knows (the projector computes it once per detection, from its camera,
    so fusion need not). None when nobody said; a row of NaN where that row's is unknown.

    ``stature`` (N,): the person's head height as measured from the box at the fitted feet
    (``bevflow.stature``), NaN where the box does not measure it (the default). ``height`` is
    the fit's, from its grid of a few heights."""

    xy: FloatArray
    height: FloatArray
    radius: FloatArray
    camera: IntArray
    score: FloatArray
    occluded: NDArray[np.bool_]
    covariance: FloatArray | None
    stature: FloatArray

    # Written out rather than generated, as for Boxes: any array-like in, checked arrays held.
    def __init__(
        self,
        xy: ArrayLike,
        height: ArrayLike | None = None,
        radius: ArrayLike | None = None,
        camera: ArrayLike | None = None,
        score: ArrayLike | None = None,
        occluded: ArrayLike | None = None,
        covariance: ArrayLike | None = None,
        stature: ArrayLike | None = None,
    ) -> None:
        rows = _rows("xy", xy, 2)
        n = len(rows)
        object.__setattr__(self, "xy", rows)
        object.__setattr__(self, "height", _column("height", height, n, 1.7, np.float64))
        object.__setattr__(self, "radius", _column("radius", radius, n, 0.3, np.float64))
        object.__setattr__(self, "camera", _column("camera", camera, n, -1, np.int64))
        object.__setattr__(self, "score", _column("score", score, n, 1.0, np.float64))
        object.__setattr__(self, "occluded", _column("occluded", occluded, n, False, np.bool_))
        object.__setattr__(self, "covariance", None if covariance is None else _covariance(covariance, n))
        object.__setattr__(self, "stature", _column("stature", stature, n, np.nan, np.float64))

    @classmethod
    def empty(cls) -> Cylinders:
        return cls(xy=np.zeros((0, 2)))

    def __len__(self) -> int:
        return len(self.xy)

    def __getitem__(self, index: RowIndex) -> Cylinders:
        return Cylinders(
            xy=self.xy[index].reshape(-1, 2),
            height=self.height[index],
            radius=self.radius[index],
            camera=self.camera[index],
            score=self.score[index],
            occluded=self.occluded[index],
            covariance=None if self.covariance is None else self.covariance[index].reshape(-1, 2, 2),
            stature=self.stature[index],
        )

    def with_camera(self, camera: int) -> Cylinders:
        return replace(self, camera=np.full(len(self), camera, dtype=np.int64))

    def near(self, centre_xy: ArrayLike, radius_m: float | None) -> NDArray[np.bool_]:
        """Which rows have their feet within ``radius_m`` of ``centre_xy`` on the floor (every row
        when ``radius_m`` is None; rows with unknown feet count as near, for fusion to judge)."""
        if radius_m is None:
            return np.ones(len(self), dtype=bool)
        distance = np.linalg.norm(self.xy - np.asarray(centre_xy, dtype=np.float64)[:2], axis=1)
        near: NDArray[np.bool_] = ~(distance > radius_m)
        return near

    @staticmethod
    def merge(parts: list[Cylinders]) -> Cylinders:
        """The rows of every part, in order. Covariances are kept when any part has them (NaN
        rows for the parts that have none)."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return Cylinders.empty()
        covariance = None
        if any(p.covariance is not None for p in parts):
            covariance = np.concatenate(
                [p.covariance if p.covariance is not None else np.full((len(p), 2, 2), np.nan) for p in parts]
            )
        return Cylinders(
            xy=np.concatenate([p.xy for p in parts]),
            height=np.concatenate([p.height for p in parts]),
            radius=np.concatenate([p.radius for p in parts]),
            camera=np.concatenate([p.camera for p in parts]),
            score=np.concatenate([p.score for p in parts]),
            occluded=np.concatenate([p.occluded for p in parts]),
            covariance=covariance,
            stature=np.concatenate([p.stature for p in parts]),
        )
