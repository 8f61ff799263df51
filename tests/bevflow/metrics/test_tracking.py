"""Tracking scores on hand-made sequences, and agreement with motmetrics on random ones."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bevflow.metrics.tracking import TrackingScores, score_tracking

NAN = float("nan")


def _frame(*people):
    """A frame from (id, x, y) triples."""
    ids = np.array([p[0] for p in people], dtype=np.int64)
    xy = np.array([p[1:] for p in people], dtype=float).reshape(-1, 2)
    return ids, xy


def _check(scores: TrackingScores, expected: dict) -> None:
    got = scores.as_dict()
    for key, value in expected.items():
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(got[key]), key
        else:
            assert got[key] == pytest.approx(value, abs=1e-12), key


TWO_APART = [_frame((1, 0, 0), (2, 5, 0))] * 4

HAND_MADE = [
    pytest.param(
        TWO_APART,
        [_frame((10, 0.1, 0), (20, 5, 0))] * 4,
        dict(MOTA=1.0, IDF1=1.0, IDSW=0, MT=2, PT=0, ML=0, FRAG=0, tp=8, fp=0, fn=0, n_gt_ids=2,
             APE=0.05, MOTP=0.9, precision=1.0, recall=1.0, FRAG_ratio=0.0),
        id="perfect",
    ),
    pytest.param(
        # The tracker swaps the two ids at frame 2 and keeps them swapped: two switches, and the
        # best trajectory pairing shares 2 of 4 frames for each person.
        TWO_APART,
        [_frame((10, 0, 0), (20, 5, 0))] * 2 + [_frame((20, 0, 0), (10, 5, 0))] * 2,
        dict(MOTA=1 - 2 / 8, IDF1=0.5, IDP=0.5, IDR=0.5, IDSW=2, MT=2, FRAG=0, tp=8),
        id="id-swap",
    ),
    pytest.param(
        # Matched, matched, lost, matched, lost: one interruption (a trailing loss is not one).
        [_frame((1, 0, 0))] * 5,
        [_frame((7, 0, 0)), _frame((7, 0, 0)), _frame(), _frame((7, 0, 0)), _frame()],
        dict(MOTA=0.6, recall=0.6, FRAG=1, FRAG_ratio=1 / 0.6, MT=0, PT=1, ML=0, IDSW=0, IDF1=2 * 3 / 8),
        id="fragmented",
    ),
    pytest.param(
        # A new hypothesis with a new id after a gap is a switch as well as a fragmentation.
        [_frame((1, 0, 0))] * 4,
        [_frame((7, 0, 0)), _frame(), _frame((8, 0, 0)), _frame((8, 0, 0))],
        dict(MOTA=1 - 2 / 4, FRAG=1, IDSW=1, MT=0, PT=1, recall=0.75, IDF1=2 * 2 / 7),
        id="re-acquired-under-new-id",
    ),
    pytest.param(
        # Frame 1: the remembered hypothesis 10 (0.4 m away) is kept although 20 is closer, so
        # 20 is the false positive. MODP, matching each frame afresh, takes 20 instead.
        [_frame((1, 0, 0))] * 2,
        [_frame((10, 0.4, 0)), _frame((10, 0.4, 0), (20, 0.05, 0))],
        dict(IDSW=0, tp=2, fp=1, fn=0, MOTA=0.5, MODA=0.5, APE=0.4, MOTP=0.2, MODP=(0.2 + 0.9) / 2),
        id="previous-match-kept",
    ),
    pytest.param(
        # Hypothesis 10 follows person 1, then drifts 1 m away onto person 2, who was matched
        # to 20 before: a switch for person 2, and person 1 is missed.
        [_frame((1, 0, 0), (2, 3, 0)), _frame((1, 0, 0), (2, 0.9, 0))],
        [_frame((10, 0, 0), (20, 3, 0)), _frame((10, 1.0, 0))],
        dict(IDSW=1, tp=3, fp=0, fn=1, MOTA=1 - 2 / 4),
        id="hypothesis-taken-over",
    ),
    pytest.param(
        [_frame((1, 0, 0))] * 3,
        [_frame((5, 2, 2))] * 3,
        dict(MOTA=1 - 6 / 3, ML=1, PT=0, MT=0, ML_fraction=1.0, FRAG=0, tp=0, fp=3, fn=3,
             MOTP=NAN, APE=NAN, IDF1=0.0, recall=0.0, FRAG_ratio=NAN),
        id="never-found",
    ),
    pytest.param(
        [_frame((1, 0, 0))] * 2,
        [_frame((5, NAN, NAN)), _frame((5, 0.1, 0))],
        dict(tp=1, fp=0, fn=1, MOTA=0.5, PT=1, FRAG=0),
        id="nan-hypothesis-ignored",
    ),
    pytest.param(
        [], [],
        dict(MOTA=NAN, MOTP=NAN, IDF1=NAN, tp=0, n_gt_ids=0, frames=0, MT=0, MT_fraction=NAN),
        id="empty",
    ),
]


@pytest.mark.parametrize(("gt", "hyp", "expected"), HAND_MADE)
def test_score_tracking_hand_made(gt, hyp, expected) -> None:
    _check(score_tracking(gt, hyp, threshold_m=0.5), expected)


@pytest.mark.parametrize(
    ("gt", "hyp", "message"),
    [
        pytest.param([_frame((1, 0, 0))], [], "frames", id="frame-count"),
        pytest.param([_frame((1, 0, 0), (1, 2, 0))], [_frame()], "more than once", id="duplicate-gt-id"),
        pytest.param([_frame()], [_frame((3, 0, 0), (3, 2, 0))], "more than once", id="duplicate-hyp-id"),
        pytest.param([(np.array([1, 2]), np.zeros((1, 2)))], [_frame()], "ids but", id="length-mismatch"),
        pytest.param([(np.array([1.5]), np.zeros((1, 2)))], [_frame()], "integers", id="float-ids"),
        pytest.param([_frame((1, NAN, 0))], [_frame()], "NaN", id="nan-ground-truth"),
    ],
)
def test_score_tracking_errors(gt, hyp, message) -> None:
    with pytest.raises(ValueError, match=message):
        score_tracking(gt, hyp)


# --- agreement with motmetrics --------------------------------------------------------------


def _random_sequence(seed: int, n_people: int = 8, n_frames: int = 40, room_m: float = 5.0):
    """People walking in a small room, and a flawed tracker: noise, misses, id changes and
    swaps, false positives."""
    rng = np.random.default_rng(seed)
    start = rng.integers(0, n_frames - 5, n_people)
    end = np.minimum(start + rng.integers(5, n_frames, n_people), n_frames)
    pos = rng.uniform(0, room_m, (n_people, 2))
    hyp_id = np.arange(n_people) + 100
    next_id = 1000
    gt, hyp = [], []
    for t in range(n_frames):
        pos += rng.normal(0, 0.2, pos.shape)
        alive = np.flatnonzero((start <= t) & (t < end))
        if rng.random() < 0.1 and len(alive) >= 2:  # the tracker swaps two ids
            a, b = rng.choice(alive, 2, replace=False)
            hyp_id[[a, b]] = hyp_id[[b, a]]
        renew = rng.random(n_people) < 0.03  # the tracker loses someone and starts afresh
        hyp_id[renew] = next_id + np.arange(renew.sum())
        next_id += int(renew.sum())
        seen = alive[rng.random(len(alive)) > 0.15]
        est = pos[seen] + rng.normal(0, 0.18, (len(seen), 2))
        n_fp = rng.poisson(0.5)
        fp_xy = rng.uniform(0, room_m, (n_fp, 2))
        fp_id = next_id + np.arange(n_fp)
        next_id += n_fp
        gt.append((alive.astype(np.int64), pos[alive].copy()))
        hyp.append((np.concatenate([hyp_id[seen], fp_id]).astype(np.int64), np.concatenate([est, fp_xy])))
    return gt, hyp


def _motmetrics_summary(gt, hyp, threshold: float) -> dict:
    mm = pytest.importorskip("motmetrics")
    acc = mm.MOTAccumulator(auto_id=True)
    for (g_ids, g_xy), (h_ids, h_xy) in zip(gt, hyp, strict=True):
        d = np.linalg.norm(g_xy.reshape(-1, 1, 2) - h_xy.reshape(1, -1, 2), axis=2)
        d[d > threshold] = np.nan
        acc.update(g_ids, h_ids, d)
    names = ["mota", "motp", "idf1", "idp", "idr", "num_switches", "mostly_tracked", "partially_tracked",
             "mostly_lost", "num_fragmentations", "precision", "recall", "num_false_positives", "num_misses"]
    return mm.metrics.create().compute(acc, metrics=names).to_dict()


def _agree(ours: TrackingScores, theirs: dict, threshold: float) -> None:
    assert ours.MOTA == pytest.approx(theirs["mota"], abs=1e-12)
    assert ours.IDF1 == pytest.approx(theirs["idf1"], abs=1e-12)
    assert ours.IDP == pytest.approx(theirs["idp"], abs=1e-12)
    assert ours.IDR == pytest.approx(theirs["idr"], abs=1e-12)
    assert ours.IDSW == theirs["num_switches"]
    assert (ours.MT, ours.PT, ours.ML) == (theirs["mostly_tracked"], theirs["partially_tracked"], theirs["mostly_lost"])
    assert ours.FRAG == theirs["num_fragmentations"]
    assert (ours.fp, ours.fn) == (theirs["num_false_positives"], theirs["num_misses"])
    assert ours.precision == pytest.approx(theirs["precision"], abs=1e-12)
    assert ours.recall == pytest.approx(theirs["recall"], abs=1e-12)
    # motmetrics' MOTP is the mean matched distance: our APE. Our MOTP is 1 - APE / threshold.
    assert ours.APE == pytest.approx(theirs["motp"], abs=1e-12, nan_ok=True)
    assert ours.MOTP == pytest.approx(1 - theirs["motp"] / threshold, abs=1e-12, nan_ok=True)


@pytest.mark.parametrize(
    ("seed", "n_people", "room_m"),
    [(seed, 8, 5.0) for seed in range(8)] + [(seed, 30, 2.5) for seed in range(3)],  # sparse and crowded
)
def test_agrees_with_motmetrics_on_random_sequences(seed: int, n_people: int, room_m: float) -> None:
    gt, hyp = _random_sequence(seed, n_people=n_people, n_frames=30, room_m=room_m)
    ours = score_tracking(gt, hyp, threshold_m=0.5)
    assert ours.IDSW > 0 and ours.FRAG > 0 and ours.fp > 0  # the sequence exercises every count
    _agree(ours, {k: v[0] for k, v in _motmetrics_summary(gt, hyp, 0.5).items()}, 0.5)


@pytest.mark.parametrize(
    ("gt", "hyp", "expected"), [p for p in HAND_MADE if p.id not in {"empty", "nan-hypothesis-ignored"}]
)
def test_agrees_with_motmetrics_on_hand_made_sequences(gt, hyp, expected) -> None:
    ours = score_tracking(gt, hyp, threshold_m=0.5)
    theirs = {k: v[0] for k, v in _motmetrics_summary(gt, hyp, 0.5).items()}
    _agree(ours, theirs, 0.5)
