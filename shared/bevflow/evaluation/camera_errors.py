"""Each camera's own views against the truth: which way, and how far, a camera misses the people it sees.

A replay scores what fusion and the tracker make of every camera together; when a figure is poor,
the first question of whoever installed the cameras is which camera is at fault and how. So each
camera's strong views (``bevflow.cylinder``: score > 0, feet on the floor) are matched one to one
to the annotated people within ``threshold_m`` (least total distance), and each match's error,
view minus truth, is split along the camera's line of sight to that person and across it:

- ``across_mrad``: the bearing's mean error, milliradians, positive anticlockwise seen from above.
  A bearing off by the same angle at every range is a camera turned on its mount, or a lens whose
  calibration misses part of the image: refine the calibration.
- ``along_m``: the range's mean error, positive beyond the person. A side view's range hangs on its
  box's bottom edge, so its spread is wide; its bias is the feet model's or the camera's height.
- ``lag_s``: the least-squares time offset of the errors against the people's own velocity
  (central differences of the truth): the views sit where the people were ``lag_s`` later.
  Cameras whose frames carry one frame number but were not captured at one instant show as
  different lags; only their differences matter, since the truth's own clock is one more.
  None where too few matches moved (``MIN_MOVING`` at ``MOVING_MPS`` or faster).

The three are read apart from each other only as people walk every way: where everyone walks one
way, a lag moves the views along that way and so shows in the bearing and range too, and the
range's bias in the lag.

On CMC2 (``docs/RESULTS.md``) all four cameras' bearings turn clockwise, 11–22 mrad on average
(0.05 m at 3.5 m), and their lags spread over 0.16 s (−0.06 s to +0.10 s). The people three
cameras agree on give the same, without any truth, to within 7 mrad and 0.05 s (each view against
the others' fused position). The pipeline does not correct them: turning and shifting each
camera's views by such estimates, learnt as the replay went, lifted the mean MOTA of twelve
perturbed copies from 0.876 to 0.883 and lowered their IDF1 from 0.604 to 0.584 (by the truth's
own figures: 0.889 and 0.585).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from bevflow.camera import Camera
from bevflow.datasets.mot import WorldTruth
from bevflow.detections import Cylinders

FloatArray = NDArray[np.float64]

MOVING_MPS = 0.3  # a person slower than this says little about a lag
MIN_MOVING = 10  # moving matches a lag needs
MIN_RANGE_M = 0.1  # nearer the point below the camera, a bearing means nothing


@dataclass(frozen=True)
class CameraError:
    """One camera's views against the truth (module docstring); NaN where it matched nobody."""

    camera_id: str
    views: int  # strong views matched to a person
    across_mrad: float
    across_spread_mrad: float  # standard deviation
    along_m: float
    along_spread_m: float
    lag_s: float | None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class CameraErrorSamples:
    """The matches of every camera, gathered frame by frame, then summed up (``errors``)."""

    def __init__(self, camera_ids: Sequence[str], cameras: Sequence[Camera], truth: WorldTruth, fps: float,
                 threshold_m: float = 0.5) -> None:  # fmt: skip
        self.camera_ids, self.cameras, self.truth, self.fps = tuple(camera_ids), list(cameras), truth, fps
        self.threshold_m = threshold_m
        # Per camera, one row a match: along, across, range, then the error and the velocity (x, y).
        self._rows: list[list[FloatArray]] = [[] for _ in camera_ids]

    def add(self, frame: int, per_camera: dict[str, Cylinders]) -> None:
        """The views each camera gave of ``frame`` (its cylinders, as the projector made them)."""
        ids, truth_xy = self.truth.at(frame)
        if not len(ids):
            return
        velocity = self._velocity(frame, ids)
        for index, camera_id in enumerate(self.camera_ids):
            views = per_camera.get(camera_id)
            if views is None or not len(views):
                continue
            views = views[(views.score > 0) & np.isfinite(views.xy).all(axis=1)]
            gap = np.linalg.norm(views.xy[:, None] - truth_xy[None], axis=2)
            view, person = linear_sum_assignment(np.where(gap < self.threshold_m, gap, 1e6))
            # Right below a camera (a ceiling view's centre) a person has no line of sight to split along.
            sight = truth_xy[person] - self.cameras[index].center[:2]
            distance = np.linalg.norm(sight, axis=1)
            close = (gap[view, person] < self.threshold_m) & (distance >= MIN_RANGE_M)
            view, person, sight, distance = view[close], person[close], sight[close], distance[close]
            along = sight / distance[:, None]
            across = np.column_stack([-along[:, 1], along[:, 0]])  # anticlockwise of the line of sight
            error = views.xy[view] - truth_xy[person]
            self._rows[index].append(np.column_stack([
                (error * along).sum(axis=1), (error * across).sum(axis=1), distance, error, velocity[person],
            ]))

    def errors(self) -> tuple[CameraError, ...]:
        """Each camera's summary, in the order of ``camera_ids``."""
        return tuple(self._summary(camera_id, rows) for camera_id, rows in zip(self.camera_ids, self._rows, strict=True))

    def _velocity(self, frame: int, ids: NDArray[np.int64]) -> FloatArray:
        """Each person's velocity from the frames either side (NaN without both), m/s."""
        before, after = _where(ids, *self.truth.at(frame - 1)), _where(ids, *self.truth.at(frame + 1))
        return (after - before) * self.fps / 2.0

    def _summary(self, camera_id: str, rows: list[FloatArray]) -> CameraError:
        m = np.concatenate(rows) if rows else np.zeros((0, 7))
        if not len(m):
            return CameraError(camera_id, 0, float("nan"), float("nan"), float("nan"), float("nan"), None)
        along, across, distance = m[:, 0], m[:, 1], m[:, 2]
        bearing = across / distance * 1e3
        return CameraError(camera_id, len(m), float(bearing.mean()), float(bearing.std()), float(along.mean()),
                           float(along.std()), _lag(m[:, 3:5], m[:, 5:7]))  # fmt: skip


def _where(ids: NDArray[np.int64], known: NDArray[np.int64], xy: FloatArray) -> FloatArray:
    """The position of each of ``ids`` among the people ``known`` at ``xy``; NaN for the absent."""
    out = np.full((len(ids), 2), np.nan)
    if not len(known):
        return out
    order = np.argsort(known)
    slot = np.minimum(np.searchsorted(known[order], ids), len(known) - 1)
    present = known[order][slot] == ids
    out[present] = xy[order][slot[present]]
    return out


def _lag(error: FloatArray, velocity: FloatArray) -> float | None:
    """The least-squares t of error ≈ t · velocity over the moving matches; None with too few."""
    moving = np.isfinite(velocity).all(axis=1) & (np.linalg.norm(np.nan_to_num(velocity), axis=1) >= MOVING_MPS)
    if moving.sum() < MIN_MOVING:
        return None
    v = velocity[moving]
    return float((error[moving] * v).sum() / (v * v).sum())
