"""MODA, MODP, precision, recall, F1 and APE on hand-worked frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bevflow.metrics.detection import DetectionScores, score_detections

NAN = float("nan")


def _frames(*frames):
    return [np.array(f, dtype=float).reshape(-1, 2) for f in frames]


@pytest.mark.parametrize(
    ("gt", "est", "threshold", "expected"),
    [
        pytest.param(
            _frames([[0, 0], [2, 0]]), _frames([[0, 0], [2, 0]]), 0.5,
            dict(tp=2, fp=0, fn=0, MODA=1.0, MODP=1.0, precision=1.0, recall=1.0, F1=1.0, APE=0.0),
            id="perfect",
        ),
        pytest.param(
            # d = 0.25 with a 0.5 m threshold: each match contributes 1 - 0.5 = 0.5 to MODP.
            _frames([[0, 0]]), _frames([[0.25, 0]]), 0.5,
            dict(tp=1, fp=0, fn=0, MODA=1.0, MODP=0.5, precision=1.0, recall=1.0, F1=1.0, APE=0.25),
            id="offset-quarter-metre",
        ),
        pytest.param(
            # Frame 1: gt (0,0),(3,0); est (0.1,0) and a false one at (10,10): TP 1, FP 1, FN 1.
            # Frame 2: gt (1,1); est (1,1.3): TP 1.
            # N_gt 3, MODA 1 - 2/3, P 2/3, R 2/3, F1 = 4/6, APE (0.1+0.3)/2, MODP (0.8+0.4)/2.
            _frames([[0, 0], [3, 0]], [[1, 1]]), _frames([[0.1, 0], [10, 10]], [[1, 1.3]]), 0.5,
            dict(tp=2, fp=1, fn=1, MODA=1 / 3, MODP=0.6, precision=2 / 3, recall=2 / 3, F1=2 / 3, APE=0.2),
            id="two-frames-mixed",
        ),
        pytest.param(
            # Three estimates, one person: one TP, two FP; MODA = 1 - 2/1 = -1.
            _frames([[0, 0]]), _frames([[0, 0], [0.1, 0], [0.2, 0]]), 0.5,
            dict(tp=1, fp=2, fn=0, MODA=-1.0, MODP=1.0, precision=1 / 3, recall=1.0, F1=0.5, APE=0.0),
            id="duplicates-are-false-positives",
        ),
        pytest.param(
            _frames([[0, 0]]), _frames([[NAN, NAN], [0.6, 0]]), 0.5,
            dict(tp=0, fp=1, fn=1, MODA=-1.0, MODP=NAN, precision=0.0, recall=0.0, F1=0.0, APE=NAN),
            id="nan-ignored-far-is-fp",
        ),
        pytest.param(
            _frames([[0, 0]]), _frames([[0.6, 0]]), 1.0,
            dict(tp=1, fp=0, fn=0, MODA=1.0, MODP=0.4, precision=1.0, recall=1.0, F1=1.0, APE=0.6),
            id="wider-threshold",
        ),
        pytest.param(
            _frames([]), _frames([]), 0.5,
            dict(tp=0, fp=0, fn=0, MODA=NAN, MODP=NAN, precision=NAN, recall=NAN, F1=NAN, APE=NAN),
            id="empty-frame-undefined",
        ),
        pytest.param(
            _frames([], [[1, 1]]), _frames([[4, 4]], []), 0.5,
            dict(tp=0, fp=1, fn=1, MODA=-1.0, MODP=NAN, precision=0.0, recall=0.0, F1=0.0, APE=NAN),
            id="frames-are-not-mixed",
        ),
    ],
)
def test_score_detections_hand_worked(gt, est, threshold, expected) -> None:
    scores = score_detections(gt, est, threshold)
    got = scores.as_dict()
    for key, value in expected.items():
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(got[key]), key
        else:
            assert got[key] == pytest.approx(value, abs=1e-12), key
    assert scores.n_gt == expected["tp"] + expected["fn"]
    assert scores.frames == len(gt)


@pytest.mark.parametrize(
    ("gt", "est", "message"),
    [
        pytest.param(_frames([[0, 0]]), _frames([], []), "frames", id="frame-count"),
        pytest.param(_frames([[NAN, 0]]), _frames([]), "NaN", id="nan-ground-truth"),
        pytest.param([np.zeros((1, 3))], _frames([]), "shape", id="bad-shape"),
    ],
)
def test_score_detections_errors(gt, est, message) -> None:
    with pytest.raises(ValueError, match=message):
        score_detections(gt, est)


def test_scores_as_dict_round_trips() -> None:
    scores = score_detections(_frames([[0, 0]]), _frames([[0, 0.1]]))
    assert DetectionScores(**scores.as_dict()) == scores
    names = {"MODA", "MODP", "precision", "recall", "F1", "APE", "tp", "fp", "fn", "n_gt", "frames"}
    assert set(scores.as_dict()) == names
