from __future__ import annotations

import doctest
import importlib.util
import math

import numpy as np
import pytest

from bevflow.metrics.hota import ALPHAS, score_hota


def frames(*rows: list[tuple[int, float, float]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """One (ids, xy) frame per list of (id, x, y)."""
    return [(np.array([r[0] for r in f], dtype=np.int64), np.array([r[1:] for r in f], dtype=np.float64).reshape(-1, 2))
            for f in rows]


ONE = [(1, 0.0, 0.0)]
# alphas 0.05 .. 0.65 are reached by a similarity of 0.68, the other 6 are not
REACHED = int(np.sum(ALPHAS <= 0.68))

CASES = {
    "perfect": (frames(ONE, ONE), frames([(5, 0.0, 0.0)], [(5, 0.0, 0.0)]), (1.0, 1.0, 1.0, 1.0)),
    # every match 0.32 m off: similarity 0.68, a match at 13 of the 19 thresholds; LocA is 1 where
    # nothing matched, as in TrackEval
    "off by 0.32 m": (
        frames(ONE, ONE), frames([(5, 0.32, 0.0)], [(5, 0.0, 0.32)]),
        (REACHED / 19, REACHED / 19, REACHED / 19, (REACHED * 0.68 + (19 - REACHED)) / 19),
    ),
    # one person, two track ids for two frames each: every TP's pair shares 2 of 4 + 2 - 2 frames
    "identity switch": (
        frames(ONE, ONE, ONE, ONE), frames([(5, 0, 0)], [(5, 0, 0)], [(6, 0, 0)], [(6, 0, 0)]),
        (math.sqrt(0.5), 1.0, 0.5, 1.0),
    ),
    # a second, far track beside the right one: half the detections are false
    "false positive": (
        frames(ONE, ONE), frames([(5, 0, 0), (6, 9, 9)], [(5, 0, 0), (6, 9, 9)]), (math.sqrt(0.5), 0.5, 1.0, 1.0),
    ),
    # a track that comes one frame late
    "late start": (frames(ONE, ONE), frames([], [(5, 0, 0)]), (math.sqrt(0.5 * 0.5), 0.5, 0.5, 1.0)),
    "no tracks": (frames(ONE, ONE), frames([], []), (0.0, 0.0, 0.0, 1.0)),
    "nobody there": (frames([], []), frames([(5, 0, 0)], []), (0.0, 0.0, 0.0, 1.0)),
    "no frames": ([], [], (0.0, 0.0, 0.0, 1.0)),
    "unplaced tracks are ignored": (frames(ONE), [(np.array([5, 6]), np.array([[0.0, 0.0], [np.nan, np.nan]]))],
                                    (1.0, 1.0, 1.0, 1.0)),
}


@pytest.mark.parametrize(("gt", "hyp", "expected"), CASES.values(), ids=CASES.keys())
def test_hand_computed(gt, hyp, expected) -> None:
    s = score_hota(gt, hyp)
    assert (s.HOTA, s.DetA, s.AssA, s.LocA) == pytest.approx(expected)


def test_similarity_falls_to_zero_at_the_zero_distance() -> None:
    # 0.6 m off: nothing at 1 m matches past alpha 0.4; at 2 m (TrackEval's default) alpha 0.7
    near = score_hota(frames(ONE), frames([(5, 0.6, 0.0)]), zero_distance_m=1.0)
    far = score_hota(frames(ONE), frames([(5, 0.6, 0.0)]), zero_distance_m=2.0)
    assert near.DetA == pytest.approx(np.sum(ALPHAS <= 0.4 + 1e-9) / 19)
    assert far.DetA == pytest.approx(np.sum(ALPHAS <= 0.7 + 1e-9) / 19)


@pytest.mark.parametrize(
    ("gt", "hyp", "error"),
    [
        (frames(ONE), [], "1 frames but hyp_frames has 0"),
        ([(np.array([1, 1]), np.zeros((2, 2)))], frames(ONE), "an id appears more than once"),
        ([(np.array([1]), np.zeros((2, 2)))], frames(ONE), "1 ids but 2 positions"),
    ],
)
def test_misuse_raises(gt, hyp, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        score_hota(gt, hyp)


def random_sequence(seed: int, n_frames: int = 30, people: int = 6) -> tuple[list, list]:
    """People wandering; tracks that follow them with noise, swap ids, miss and invent people."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 4, (people, 2))
    gt, hyp = [], []
    track_of = np.arange(people) + 100
    for _ in range(n_frames):
        xy += rng.normal(0, 0.15, xy.shape)
        present = rng.random(people) > 0.1
        gt.append((np.flatnonzero(present), xy[present].copy()))
        if rng.random() < 0.15:  # two tracks swap people
            i, j = rng.choice(people, 2, replace=False)
            track_of[[i, j]] = track_of[[j, i]]
        if rng.random() < 0.1:  # a track is lost and a new one starts
            track_of[rng.integers(people)] = rng.integers(1000, 10**6)
        seen = present & (rng.random(people) > 0.15)
        est = xy[seen] + rng.normal(0, 0.25, (int(seen.sum()), 2))
        ghosts = rng.integers(0, 3)
        hyp.append((np.r_[track_of[seen], 10**7 + rng.choice(50, ghosts, replace=False)],
                    np.r_[est, rng.uniform(0, 4, (ghosts, 2))]))
    return gt, hyp


def trackeval_hota(gt: list, hyp: list, zero_distance_m: float) -> dict[str, float]:
    """TrackEval's own HOTA on the same frames, with TrackEval's euclidean similarity."""
    from trackeval.datasets._base_dataset import _BaseDataset
    from trackeval.metrics import HOTA

    gt_unique = np.unique(np.concatenate([g[0] for g in gt]))
    hyp_unique = np.unique(np.concatenate([h[0] for h in hyp]))
    data = {
        "gt_ids": [np.searchsorted(gt_unique, g[0]) for g in gt],
        "tracker_ids": [np.searchsorted(hyp_unique, h[0]) for h in hyp],
        "similarity_scores": [_BaseDataset._calculate_euclidean_similarity(g[1], h[1], zero_distance_m)
                              for g, h in zip(gt, hyp, strict=True)],
        "num_gt_ids": len(gt_unique), "num_tracker_ids": len(hyp_unique),
        "num_gt_dets": sum(len(g[0]) for g in gt), "num_tracker_dets": sum(len(h[0]) for h in hyp),
        "num_timesteps": len(gt),
    }
    res = HOTA().eval_sequence(data)
    return {k: float(np.mean(res[k])) for k in ("HOTA", "DetA", "AssA", "LocA", "DetRe", "DetPr", "AssRe", "AssPr")}


@pytest.mark.skipif(importlib.util.find_spec("trackeval") is None,
                    reason="trackeval is not installed (pip install --no-deps trackeval; ./run test installs it)")
@pytest.mark.parametrize(("seed", "zero_distance_m"), [(0, 1.0), (1, 1.0), (2, 2.0), (3, 0.5)])
def test_same_as_trackeval(seed: int, zero_distance_m: float) -> None:
    gt, hyp = random_sequence(seed)
    ours = score_hota(gt, hyp, zero_distance_m).as_dict()
    theirs = trackeval_hota(gt, hyp, zero_distance_m)
    assert 0.2 < theirs["HOTA"] < 0.95  # a sequence with something of everything to score
    assert {k: ours[k] for k in theirs} == pytest.approx(theirs, abs=1e-12)


def test_docstring_example() -> None:
    import bevflow.metrics.hota

    assert doctest.testmod(bevflow.metrics.hota).failed == 0
