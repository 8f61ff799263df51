"""Multi-object tracking scores on the floor: CLEAR-MOT, identity (IDF1), MT/PT/ML, FRAG.

Every frame is a pair ``(ids, xy)``: integer track ids (N,) and feet positions (N, 2) in
metres, for the ground truth and for the tracker output (the hypotheses).

CLEAR-MOT matching (Bernardin & Stiefelhagen 2008, as in motmetrics), frame by frame:

1. A ground-truth person keeps the hypothesis it was last matched to (in any earlier frame)
   if that hypothesis is present and within ``threshold_m``.
2. The rest are matched by Hungarian on distance (most pairs first, then least distance).
3. A Hungarian match whose person was last matched to another hypothesis is an identity
   switch (IDSW).

From those matches (TP), unmatched hypotheses (FP), unmatched ground truth (FN), N_gt = TP + FN:

- MOTA = 1 - (FN + FP + IDSW) / N_gt
- MOTP = Σ (1 - d / threshold) / TP, the ground-plane convention shared with MODP (1 is
  perfect). motmetrics' ``motp`` is instead the mean matched distance: that is ``APE`` here.
- precision, recall, F1, APE (mean matched distance, m) from the same matches.
- MT / PT / ML: people matched in >= 80 % / between / < 20 % of the frames they are present in
  (their life span); counts and fractions of ``n_gt_ids``.
- FRAG: how many times a person goes from matched to unmatched and is matched again later
  (the interruptions of their track), as in motmetrics; FRAG_ratio = FRAG / recall, the
  paper's definition.
- IDF1, IDP, IDR (Ristani et al. 2016): ground-truth and hypothesis trajectories are paired
  one-to-one to maximise the frames in which they lie within the threshold (IDTP);
  IDF1 = 2 IDTP / (N_gt + N_hyp).
- MODA, MODP: the detection scores of ``bevflow.metrics.detection`` (ids ignored, each frame
  matched on its own).

Hypothesis rows holding NaN are ignored; ids must be unique within a frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bevflow.metrics.detection import modp_terms, ratio, score_detections
from bevflow.metrics.matching import as_points, assign_edges, gated_pairs

IntArray = NDArray[np.int64]
Frame = tuple[np.ndarray, np.ndarray]

MOSTLY_TRACKED = 0.8
MOSTLY_LOST = 0.2


@dataclass(frozen=True)
class TrackingScores:
    """Tracking scores over one sequence (see the module docstring for the definitions)."""

    MOTA: float
    MOTP: float
    IDF1: float
    IDP: float
    IDR: float
    IDSW: int
    MT: int
    PT: int
    ML: int
    MT_fraction: float
    PT_fraction: float
    ML_fraction: float
    FRAG: int
    FRAG_ratio: float
    precision: float
    recall: float
    F1: float
    APE: float
    MODA: float
    MODP: float
    tp: int
    fp: int
    fn: int
    n_gt: int
    n_gt_ids: int
    frames: int

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class _Frame:
    gt: IntArray  # dense ground-truth indices
    hyp: IntArray  # dense hypothesis indices
    gt_xy: np.ndarray
    hyp_xy: np.ndarray


def score_tracking(
    gt_frames: Sequence[Frame], hyp_frames: Sequence[Frame], threshold_m: float = 0.5
) -> TrackingScores:
    """Score tracker output against ground truth; ``gt_frames[k]`` and ``hyp_frames[k]`` are the
    same instant, each an ``(ids, xy)`` pair."""
    if len(gt_frames) != len(hyp_frames):
        raise ValueError(f"gt_frames has {len(gt_frames)} frames but hyp_frames has {len(hyp_frames)}")
    if threshold_m < 0:
        raise ValueError(f"threshold_m must be >= 0, got {threshold_m}")
    frames, n_gt_ids, n_hyp_ids = _densify(gt_frames, hyp_frames)

    last_hyp = np.full(n_gt_ids, -1, dtype=np.int64)  # the hypothesis each person last matched
    tp = fp = fn = idsw = 0
    distance_sum = motp_sum = 0.0
    present_ids: list[IntArray] = []  # per frame: which people are present ...
    matched_flags: list[np.ndarray] = []  # ... and whether each was matched
    overlap_pairs: list[tuple[IntArray, IntArray]] = []  # (person, hypothesis) within the gate
    for frame in frames:
        rows, cols, dist = gated_pairs(frame.gt_xy, frame.hyp_xy, threshold_m)
        overlap_pairs.append((frame.gt[rows], frame.hyp[cols]))
        gt_i, hyp_j, switched = _clear_mot_step(frame, rows, cols, dist, last_hyp)
        d = np.linalg.norm(frame.gt_xy[gt_i] - frame.hyp_xy[hyp_j], axis=1)
        tp += len(gt_i)
        fp += len(frame.hyp) - len(gt_i)
        fn += len(frame.gt) - len(gt_i)
        idsw += switched
        distance_sum += float(d.sum())
        motp_sum += modp_terms(d, threshold_m)
        flags = np.zeros(len(frame.gt), dtype=bool)
        flags[gt_i] = True
        present_ids.append(frame.gt)
        matched_flags.append(flags)

    present = np.concatenate(present_ids) if present_ids else np.zeros(0, np.int64)
    matched = np.concatenate(matched_flags) if matched_flags else np.zeros(0, bool)
    mt, pt, ml = _coverage_classes(present, matched, n_gt_ids)
    frag = _fragmentations(present, matched)
    n_hyp = sum(len(f.hyp) for f in frames)
    idtp = _identity_true_positives(overlap_pairs, n_gt_ids, n_hyp_ids)
    n_gt = tp + fn
    recall = ratio(tp, n_gt)
    detection = score_detections([f.gt_xy for f in frames], [f.hyp_xy for f in frames], threshold_m)
    return TrackingScores(
        MOTA=1.0 - ratio(fn + fp + idsw, n_gt) if n_gt else float("nan"),
        MOTP=ratio(motp_sum, tp),
        IDF1=ratio(2 * idtp, n_gt + n_hyp),
        IDP=ratio(idtp, n_hyp),
        IDR=ratio(idtp, n_gt),
        IDSW=idsw,
        MT=mt,
        PT=pt,
        ML=ml,
        MT_fraction=ratio(mt, n_gt_ids),
        PT_fraction=ratio(pt, n_gt_ids),
        ML_fraction=ratio(ml, n_gt_ids),
        FRAG=frag,
        FRAG_ratio=ratio(frag, recall),
        precision=ratio(tp, tp + fp),
        recall=recall,
        F1=ratio(2 * tp, 2 * tp + fp + fn),
        APE=ratio(distance_sum, tp),
        MODA=detection.MODA,
        MODP=detection.MODP,
        tp=tp,
        fp=fp,
        fn=fn,
        n_gt=n_gt,
        n_gt_ids=n_gt_ids,
        frames=len(frames),
    )


def _densify(gt_frames: Sequence[Frame], hyp_frames: Sequence[Frame]) -> tuple[list[_Frame], int, int]:
    """Check the frames and renumber ids 0..n-1 (separately for people and hypotheses)."""
    gt_ids, gt_xy, hyp_ids, hyp_xy = [], [], [], []
    for k, ((g_ids, g_xy), (h_ids, h_xy)) in enumerate(zip(gt_frames, hyp_frames, strict=True)):
        g_ids, g_xy = _frame_arrays(g_ids, g_xy, f"gt_frames[{k}]")
        h_ids, h_xy = _frame_arrays(h_ids, h_xy, f"hyp_frames[{k}]")
        if not np.isfinite(g_xy).all():
            raise ValueError(f"gt_frames[{k}] holds NaN or infinite positions")
        placed = np.isfinite(h_xy).all(axis=1)
        gt_ids.append(g_ids)
        gt_xy.append(g_xy)
        hyp_ids.append(h_ids[placed])
        hyp_xy.append(h_xy[placed])
    gt_unique, gt_dense = _renumber(gt_ids)
    hyp_unique, hyp_dense = _renumber(hyp_ids)
    frames = [_Frame(g, h, gx, hx) for g, h, gx, hx in zip(gt_dense, hyp_dense, gt_xy, hyp_xy, strict=True)]
    return frames, len(gt_unique), len(hyp_unique)


def _frame_arrays(ids: object, xy: object, name: str) -> tuple[IntArray, np.ndarray]:
    ids_arr = np.asarray(ids).reshape(-1)
    if ids_arr.size and not np.issubdtype(ids_arr.dtype, np.integer):
        raise ValueError(f"{name}: ids must be integers, got {ids_arr.dtype}")
    ids_arr = ids_arr.astype(np.int64)
    xy_arr = as_points(xy, f"{name} xy")
    if len(ids_arr) != len(xy_arr):
        raise ValueError(f"{name}: {len(ids_arr)} ids but {len(xy_arr)} positions")
    if len(np.unique(ids_arr)) != len(ids_arr):
        raise ValueError(f"{name}: an id appears more than once in the frame")
    return ids_arr, xy_arr


def _renumber(ids_per_frame: list[IntArray]) -> tuple[IntArray, list[IntArray]]:
    if not ids_per_frame:
        return np.zeros(0, np.int64), []
    unique, inverse = np.unique(np.concatenate(ids_per_frame), return_inverse=True)
    bounds = np.cumsum([len(i) for i in ids_per_frame])[:-1]
    return unique, np.split(inverse.astype(np.int64), bounds)


def _clear_mot_step(
    frame: _Frame, rows: IntArray, cols: IntArray, dist: np.ndarray, last_hyp: IntArray
) -> tuple[IntArray, IntArray, int]:
    """One frame of CLEAR-MOT matching; updates ``last_hyp`` in place.

    Returns matched (gt row, hyp row) and the number of identity switches."""
    keep = last_hyp[frame.gt[rows]] == frame.hyp[cols]
    kept_r, kept_c = rows[keep], cols[keep]
    # Two people may both remember the same hypothesis; like motmetrics, the first listed wins.
    order = np.lexsort((kept_c, kept_r))
    kept_r, kept_c = kept_r[order], kept_c[order]
    _, first = np.unique(kept_c, return_index=True)
    kept_r, kept_c = kept_r[first], kept_c[first]

    free = ~np.isin(rows, kept_r) & ~np.isin(cols, kept_c)
    new_r, new_c = assign_edges(rows[free], cols[free], dist[free], len(frame.gt), len(frame.hyp))
    previous = last_hyp[frame.gt[new_r]]
    switched = int(np.count_nonzero((previous >= 0) & (previous != frame.hyp[new_c])))

    gt_i = np.concatenate([kept_r, new_r])
    hyp_j = np.concatenate([kept_c, new_c])
    last_hyp[frame.gt[gt_i]] = frame.hyp[hyp_j]
    return gt_i, hyp_j, switched


def _coverage_classes(present: IntArray, matched: np.ndarray, n_gt_ids: int) -> tuple[int, int, int]:
    """MT, PT, ML counts from the matched share of each person's life span."""
    if n_gt_ids == 0:
        return 0, 0, 0
    life = np.bincount(present, minlength=n_gt_ids)
    covered = np.bincount(present, weights=matched, minlength=n_gt_ids)
    share = covered / np.maximum(life, 1)
    mt = int(np.count_nonzero(share >= MOSTLY_TRACKED))
    ml = int(np.count_nonzero(share < MOSTLY_LOST))
    return mt, n_gt_ids - mt - ml, ml


def _fragmentations(present: IntArray, matched: np.ndarray) -> int:
    """Matched → unmatched transitions of each person that are followed by a later match."""
    if len(present) == 0:
        return 0
    order = np.argsort(present, kind="stable")  # frames stay in time order within a person
    person, hit = present[order], matched[order]
    same_person = person[1:] == person[:-1]
    dropped = same_person & hit[:-1] & ~hit[1:]  # transition into a miss at index k + 1
    # A drop counts only if the same person is matched again afterwards.
    hit_positions = np.flatnonzero(hit)
    last_hit = np.full(person.max() + 1, -1)
    np.maximum.at(last_hit, person[hit_positions], hit_positions)
    drop_at = np.flatnonzero(dropped) + 1
    return int(np.count_nonzero(last_hit[person[drop_at]] > drop_at))


def _identity_true_positives(pairs: list[tuple[IntArray, IntArray]], n_gt_ids: int, n_hyp_ids: int) -> int:
    """IDTP: frames shared within the gate under the best one-to-one trajectory pairing."""
    if not pairs or n_gt_ids == 0 or n_hyp_ids == 0:
        return 0
    g = np.concatenate([p[0] for p in pairs])
    h = np.concatenate([p[1] for p in pairs])
    if len(g) == 0:
        return 0
    key, count = np.unique(g * n_hyp_ids + h, return_counts=True)
    g, h = key // n_hyp_ids, key % n_hyp_ids
    # Trajectories that never come near each other are independent: solve each cluster alone.
    n = n_gt_ids + n_hyp_ids
    graph = coo_matrix((np.ones(len(g)), (g, h + n_gt_ids)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    idtp = 0
    edge_label = label[g]
    order = np.argsort(edge_label, kind="stable")
    for group in np.split(order, np.flatnonzero(np.diff(edge_label[order])) + 1):
        rows, r = np.unique(g[group], return_inverse=True)
        cols, c = np.unique(h[group], return_inverse=True)
        if len(group) == 1:
            idtp += int(count[group[0]])
            continue
        weight = np.zeros((len(rows), len(cols)))
        weight[r, c] = count[group]
        sel_r, sel_c = linear_sum_assignment(weight, maximize=True)
        idtp += int(weight[sel_r, sel_c].sum())
    return idtp
