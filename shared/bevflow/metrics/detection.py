"""Frame-by-frame detection scores on the floor: MODA, MODP, precision, recall, F1, APE.

Each frame's ground-truth and estimated feet positions are matched one-to-one with
``match_positions`` (Hungarian on ground distance, pairs farther than ``threshold_m`` never
match). Over all frames, with TP matched pairs, FP unmatched estimates, FN unmatched ground
truth and N_gt = TP + FN:

- MODA = 1 - (FN + FP) / N_gt  (multiple object detection accuracy; can go below 0)
- MODP = Σ_matches (1 - d / threshold) / TP  (the ground-plane convention of the WILDTRACK and
  POM evaluation kits: 1 when every match is exact, 0 when every match sits on the threshold)
- precision = TP / (TP + FP), recall = TP / N_gt, F1 = 2 TP / (2 TP + FP + FN)
- APE = mean matched distance in metres (the paper's "average positioning error")

A ratio whose denominator is zero is NaN (e.g. precision when nothing was estimated).

>>> s = score_detections([np.array([[0.0, 0.0], [3.0, 0.0]])], [np.array([[0.1, 0.0]])])
>>> s.tp, s.fp, s.fn, s.MODA, round(s.APE, 3)
(1, 0, 1, 0.5, 0.1)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from bevflow.metrics.matching import as_points, match_positions


def ratio(num: float, den: float) -> float:
    """``num / den``, NaN when ``den`` is zero."""
    return float(num) / float(den) if den else float("nan")


@dataclass(frozen=True)
class DetectionScores:
    """Detection scores summed over a sequence of frames (see the module docstring)."""

    MODA: float
    MODP: float
    precision: float
    recall: float
    F1: float
    APE: float
    tp: int
    fp: int
    fn: int
    n_gt: int
    frames: int

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_counts(
        cls, tp: int, fp: int, fn: int, distance_sum: float, modp_sum: float, frames: int
    ) -> DetectionScores:
        """Scores from the totals; ``modp_sum`` is Σ (1 - d / threshold) over the matches."""
        n_gt = tp + fn
        return cls(
            MODA=1.0 - ratio(fn + fp, n_gt) if n_gt else float("nan"),
            MODP=ratio(modp_sum, tp),
            precision=ratio(tp, tp + fp),
            recall=ratio(tp, n_gt),
            F1=ratio(2 * tp, 2 * tp + fp + fn),
            APE=ratio(distance_sum, tp),
            tp=int(tp),
            fp=int(fp),
            fn=int(fn),
            n_gt=int(n_gt),
            frames=int(frames),
        )


def modp_terms(distance: np.ndarray, threshold_m: float) -> float:
    """Σ (1 - d / threshold) over matched distances (each match's share of MODP)."""
    if threshold_m <= 0:
        return float(len(distance))  # only exact matches are possible
    return float(np.sum(1.0 - np.asarray(distance) / threshold_m))


def score_detections(
    gt: Sequence[np.ndarray], est: Sequence[np.ndarray], threshold_m: float = 0.5
) -> DetectionScores:
    """Score estimated feet positions against ground truth, one (N, 2) array per frame.

    ``gt[k]`` and ``est[k]`` belong to the same frame. Estimated rows holding NaN are ignored
    (neither true nor false positives); ground truth must be finite.
    """
    if len(gt) != len(est):
        raise ValueError(f"gt has {len(gt)} frames but est has {len(est)}")
    if threshold_m < 0:
        raise ValueError(f"threshold_m must be >= 0, got {threshold_m}")
    tp = fp = fn = 0
    distance_sum = modp_sum = 0.0
    for k, (gt_frame, est_frame) in enumerate(zip(gt, est, strict=True)):
        gt_xy = as_points(gt_frame, f"gt[{k}]")
        est_xy = as_points(est_frame, f"est[{k}]")
        if not np.isfinite(gt_xy).all():
            raise ValueError(f"gt[{k}] holds NaN or infinite positions")
        n_est = int(np.isfinite(est_xy).all(axis=1).sum())
        _, _, distance = match_positions(gt_xy, est_xy, threshold_m)
        tp += len(distance)
        fp += n_est - len(distance)
        fn += len(gt_xy) - len(distance)
        distance_sum += float(distance.sum())
        modp_sum += modp_terms(distance, threshold_m)
    return DetectionScores.from_counts(tp, fp, fn, distance_sum, modp_sum, len(gt))
