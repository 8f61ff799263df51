"""HOTA on the floor (Luiten et al. 2021): detection, association and localisation in one score.

Frames are ``(ids, xy)`` pairs as in ``bevflow.metrics.tracking``. The similarity of a person and
a track in a frame comes from their distance on the floor, as multi-camera 3D people-tracking
benchmarks score positions (TrackEval's ``_calculate_euclidean_similarity``)::

    sim = max(0, 1 - d / zero_distance_m)

TrackEval's default zero distance is 2 m (MOT15-3D: a 1 m match at similarity 0.5); ours is
``ZERO_DISTANCE_M`` = 1 m, so that similarity 0.5 is the 0.5 m match of the other floor scores.

The rest is TrackEval's HOTA, step for step: per frame, people and tracks are matched by
Hungarian on similarity weighted by how much each pair is matched over the whole sequence;
for each threshold alpha in 0.05, 0.10, ..., 0.95 a match counts when its similarity reaches
alpha, giving DetA = TP / (TP + FN + FP), AssA = the mean over TPs of TPA / (TPA + FNA + FPA)
of their pair, LocA = the mean similarity of the TPs, and HOTA = sqrt(DetA · AssA). Each score is
the mean over the thresholds. Hypothesis rows holding NaN are ignored.

>>> frame = (np.array([1]), np.array([[0.0, 0.0]]))
>>> s = score_hota([frame, frame], [frame, frame])
>>> s.HOTA, s.DetA, s.AssA, s.LocA
(1.0, 1.0, 1.0, 1.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from bevflow.metrics.matching import as_points

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Frame = tuple[np.ndarray, np.ndarray]

ALPHAS = np.arange(0.05, 0.99, 0.05)  # TrackEval's 19 thresholds, computed as it computes them
ZERO_DISTANCE_M = 1.0
_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class HotaScores:
    """The means over the alpha thresholds (module docstring)."""

    HOTA: float
    DetA: float
    AssA: float
    LocA: float
    DetRe: float
    DetPr: float
    AssRe: float
    AssPr: float
    zero_distance_m: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def score_hota(gt_frames: Sequence[Frame], hyp_frames: Sequence[Frame], zero_distance_m: float = ZERO_DISTANCE_M) -> HotaScores:
    """HOTA of tracker output against ground truth; ``gt_frames[k]`` and ``hyp_frames[k]`` are the
    same instant."""
    if len(gt_frames) != len(hyp_frames):
        raise ValueError(f"gt_frames has {len(gt_frames)} frames but hyp_frames has {len(hyp_frames)}")
    if not zero_distance_m > 0:
        raise ValueError(f"zero_distance_m must be > 0, got {zero_distance_m}")
    gt_ids, gt_xy = _dense([f[0] for f in gt_frames], [as_points(f[1], "gt xy") for f in gt_frames])
    hyp_xy_raw = [as_points(f[1], "hyp xy") for f in hyp_frames]
    placed = [np.isfinite(xy).all(axis=1) for xy in hyp_xy_raw]
    hyp_ids, hyp_xy = _dense([np.asarray(f[0]).reshape(-1)[p] for f, p in zip(hyp_frames, placed, strict=True)],
                             [xy[p] for xy, p in zip(hyp_xy_raw, placed, strict=True)])
    similarity = [_similarity(g, h, zero_distance_m) for g, h in zip(gt_xy, hyp_xy, strict=True)]
    n_gt, n_hyp = int(sum(map(len, gt_ids))), int(sum(map(len, hyp_ids)))
    if n_gt == 0 or n_hyp == 0:  # TrackEval's early returns: nothing to match
        zeros = np.zeros(len(ALPHAS))
        return _final(zeros, np.full(len(ALPHAS), float(n_gt)), np.full(len(ALPHAS), float(n_hyp)),
                      zeros, zeros, zeros, np.ones(len(ALPHAS)), zero_distance_m)
    alignment = _global_alignment(gt_ids, hyp_ids, similarity)
    return _match_frames(gt_ids, hyp_ids, similarity, alignment, zero_distance_m)


def _dense(ids: list[np.ndarray], xy: list[FloatArray]) -> tuple[list[IntArray], list[FloatArray]]:
    """Ids renumbered 0..n-1 over the sequence; checks one position per id and no id twice."""
    for k, (i, p) in enumerate(zip(ids, xy, strict=True)):
        if len(np.asarray(i).reshape(-1)) != len(p):
            raise ValueError(f"frame {k}: {len(np.asarray(i).reshape(-1))} ids but {len(p)} positions")
        if len(np.unique(i)) != len(np.asarray(i).reshape(-1)):
            raise ValueError(f"frame {k}: an id appears more than once")
    flat = [np.asarray(i, dtype=np.int64).reshape(-1) for i in ids]
    if not flat:
        return [], []
    _, inverse = np.unique(np.concatenate(flat), return_inverse=True)
    return np.split(inverse.astype(np.int64), np.cumsum([len(i) for i in flat])[:-1]), xy


def _similarity(gt_xy: FloatArray, hyp_xy: FloatArray, zero_distance_m: float) -> FloatArray:
    distance = np.linalg.norm(gt_xy[:, None, :] - hyp_xy[None, :, :], axis=2)
    similarity: FloatArray = np.maximum(0.0, 1.0 - distance / zero_distance_m)
    return similarity


def _global_alignment(gt_ids: list[IntArray], hyp_ids: list[IntArray], similarity: list[FloatArray]) -> FloatArray:
    """How much each (person, track) pair is matched over the whole sequence, 0..1."""
    n_g = 1 + max((int(g.max()) for g in gt_ids if len(g)), default=-1)
    n_h = 1 + max((int(h.max()) for h in hyp_ids if len(h)), default=-1)
    potential = np.zeros((n_g, n_h))
    gt_count, hyp_count = np.zeros(n_g), np.zeros(n_h)
    for g, h, s in zip(gt_ids, hyp_ids, similarity, strict=True):
        denominator = s.sum(0)[None, :] + s.sum(1)[:, None] - s
        share = np.zeros_like(s)
        ok = denominator > _EPS
        share[ok] = s[ok] / denominator[ok]
        potential[g[:, None], h[None, :]] += share
        gt_count[g] += 1
        hyp_count[h] += 1
    return potential / (gt_count[:, None] + hyp_count[None, :] - potential)


def _match_frames(gt_ids: list[IntArray], hyp_ids: list[IntArray], similarity: list[FloatArray],
                  alignment: FloatArray, zero_distance_m: float) -> HotaScores:
    n_a = len(ALPHAS)
    tp, fn, fp, loc = np.zeros(n_a), np.zeros(n_a), np.zeros(n_a), np.zeros(n_a)
    matches = np.zeros((n_a, *alignment.shape))
    gt_count = np.bincount(np.concatenate(gt_ids), minlength=alignment.shape[0])
    hyp_count = np.bincount(np.concatenate(hyp_ids), minlength=alignment.shape[1])
    for g, h, s in zip(gt_ids, hyp_ids, similarity, strict=True):
        if len(g) == 0 or len(h) == 0:
            fp += len(h)
            fn += len(g)
            continue
        rows, cols = linear_sum_assignment(-(alignment[g[:, None], h[None, :]] * s))
        matched_sim = s[rows, cols]
        counted = matched_sim[None, :] >= ALPHAS[:, None] - _EPS  # (alphas, matches)
        n = counted.sum(axis=1)
        tp += n
        fn += len(g) - n
        fp += len(h) - n
        loc += (counted * matched_sim[None, :]).sum(axis=1)
        a, k = np.nonzero(counted)
        np.add.at(matches, (a, g[rows[k]], h[cols[k]]), 1.0)
    union = gt_count[None, :, None] + hyp_count[None, None, :] - matches
    per_tp = np.maximum(1.0, tp)
    ass_a = (matches * matches / np.maximum(1.0, union)).sum(axis=(1, 2)) / per_tp
    ass_re = (matches * matches / np.maximum(1.0, gt_count)[None, :, None]).sum(axis=(1, 2)) / per_tp
    ass_pr = (matches * matches / np.maximum(1.0, hyp_count)[None, None, :]).sum(axis=(1, 2)) / per_tp
    loc_a = np.maximum(1e-10, loc) / np.maximum(1e-10, tp)
    return _final(tp, fn, fp, ass_a, ass_re, ass_pr, loc_a, zero_distance_m)


def _final(tp: FloatArray, fn: FloatArray, fp: FloatArray, ass_a: FloatArray, ass_re: FloatArray,
           ass_pr: FloatArray, loc_a: FloatArray, zero_distance_m: float) -> HotaScores:
    det_a = tp / np.maximum(1.0, tp + fn + fp)
    return HotaScores(
        HOTA=float(np.mean(np.sqrt(det_a * ass_a))),
        DetA=float(np.mean(det_a)),
        AssA=float(np.mean(ass_a)),
        LocA=float(np.mean(loc_a)),
        DetRe=float(np.mean(tp / np.maximum(1.0, tp + fn))),
        DetPr=float(np.mean(tp / np.maximum(1.0, tp + fp))),
        AssRe=float(np.mean(ass_re)),
        AssPr=float(np.mean(ass_pr)),
        zero_distance_m=zero_distance_m,
    )
