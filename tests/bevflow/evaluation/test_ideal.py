from __future__ import annotations

import numpy as np
import pytest

from bevflow.datasets.mot import WorldTruth
from bevflow.evaluation.ideal import ideal_tracking
from bevflow.evaluation.replay import SCORED
from bevflow.tracking.tracker import TrackerConfig

TRACKER = TrackerConfig()


def marching(people: int, frames: int, spacing_m: float, step_m: float = 0.2) -> WorldTruth:
    """``people`` walking side by side along x, ``spacing_m`` apart, ``step_m`` a frame."""
    ids = np.arange(1, people + 1, dtype=np.int64)
    return WorldTruth(
        {f: (ids, np.column_stack([np.full(people, step_m * f), spacing_m * np.arange(people)])) for f in range(frames)}
    )


def crossing(frames: int) -> WorldTruth:
    """Two people walking through each other's path at right angles, meeting mid-way."""
    ids = np.array([1, 2], dtype=np.int64)
    half = frames // 2
    return WorldTruth(
        {f: (ids, np.array([[0.2 * (f - half), 0.0], [0.0, 0.2 * (f - half) + 0.05]])) for f in range(frames)}
    )


@pytest.mark.parametrize(
    ("truth", "noise_m", "idf1", "idsw"),
    [
        (marching(3, 20, 2.0), 0.0, 0.9, 0),  # far apart, exact: only the frames before confirmation are lost
        (marching(3, 20, 2.0), 0.1, 0.9, 0),  # far apart, noisy: still one track each
        (crossing(20), 0.0, 0.9, 0),  # exact positions carry a crossing through
    ],
)
def test_the_tracker_alone_keeps_who_is_who_where_nothing_is_ambiguous(
    truth: WorldTruth, noise_m: float, idf1: float, idsw: int
) -> None:
    scores = ideal_tracking(truth, fps=4, noise_m=noise_m, tracker=TRACKER, runs=3)
    assert set(scores) == set(SCORED)
    assert scores["IDF1"].low >= idf1 and scores["IDSW"].high == idsw
    assert scores["precision"].low == 1.0  # nothing but the people was fed in


def test_noise_in_a_tight_file_costs_identities_and_runs_are_reproducible() -> None:
    tight = marching(6, 40, 0.35, step_m=0.25)
    exact = ideal_tracking(tight, 4, 0.0, TRACKER, runs=1)
    noisy = ideal_tracking(tight, 4, 0.15, TRACKER, runs=3)
    assert exact["IDSW"].high == 0 and noisy["IDSW"].mean > 0
    assert noisy["IDF1"].mean < exact["IDF1"].mean
    assert noisy["APE"].mean > exact["APE"].mean
    again = ideal_tracking(tight, 4, 0.15, TRACKER, runs=3)
    assert {k: s.as_dict() for k, s in again.items()} == {k: s.as_dict() for k, s in noisy.items()}


@pytest.mark.parametrize(
    ("truth", "fps", "noise_m", "runs", "message"),
    [
        (marching(1, 3, 1.0), 0.0, 0.1, 1, "fps must be > 0"),
        (marching(1, 3, 1.0), 4.0, -0.1, 1, "noise_m must be a number of metres >= 0"),
        (marching(1, 3, 1.0), 4.0, float("nan"), 1, "noise_m must be a number of metres >= 0"),
        (marching(1, 3, 1.0), 4.0, 0.1, 0, "runs must be >= 1"),
        (WorldTruth({}), 4.0, 0.1, 1, "the truth has no rows"),
    ],
)
def test_impossible_runs_are_refused(truth: WorldTruth, fps: float, noise_m: float, runs: int, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ideal_tracking(truth, fps, noise_m, TRACKER, runs)
