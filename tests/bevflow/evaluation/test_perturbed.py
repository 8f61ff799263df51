from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bevflow.datasets.mot import CameraRecording, DetectionRecording, read_detections, read_truth
from bevflow.detections import Boxes
from bevflow.evaluation.perturbed import SCORED, BoxPerturbation, perturbed_replays
from bevflow.evaluation.replay import replay_tracking
from bevflow.site import load_site
from tests.bevflow.evaluation.test_replay import WILDTRACK_FPS, write_recording
from tests.bevflow.evaluation.test_wildtrack_tracking import walkers

SIZE = (640, 480)
FRAMES = 50
BOXES_PER_FRAME = 20


def recording() -> DetectionRecording:
    """One camera, ``BOXES_PER_FRAME`` boxes a frame, the first of each frame at the image's left
    and top edges (clipped, as a recording's are)."""
    rng = np.random.default_rng(7)
    by_frame = {}
    for frame in range(FRAMES):
        x0, y0 = rng.uniform(0, 400, BOXES_PER_FRAME), rng.uniform(0, 200, BOXES_PER_FRAME)
        x0[0] = y0[0] = 0.0
        xyxy = np.column_stack([x0, y0, x0 + rng.uniform(20, 60, BOXES_PER_FRAME), y0 + rng.uniform(60, 200, BOXES_PER_FRAME)])
        by_frame[frame] = Boxes(xyxy, rng.uniform(0.5, 1.0, BOXES_PER_FRAME))
    return DetectionRecording((CameraRecording("cam", by_frame),))


def perturbed(drop: float, jitter_px: float, seed: int = 0) -> DetectionRecording:
    return BoxPerturbation(drop, jitter_px).apply(recording(), {"cam": SIZE}, seed)


def boxes_of(r: DetectionRecording) -> list[Boxes]:
    return [r.cameras[0].by_frame[f] for f in sorted(r.cameras[0].by_frame)]


def test_no_drop_and_no_jitter_is_the_recording_itself() -> None:
    for got, want in zip(boxes_of(perturbed(0.0, 0.0)), boxes_of(recording()), strict=True):
        np.testing.assert_array_equal(got.xyxy, want.xyxy)
        np.testing.assert_array_equal(got.confidence, want.confidence)


@pytest.mark.parametrize("drop", [0.05, 0.3, 0.7])
def test_each_box_is_dropped_with_the_given_probability(drop: float) -> None:
    kept = sum(len(b) for b in boxes_of(perturbed(drop, 0.0)))
    total = FRAMES * BOXES_PER_FRAME
    # binomial: within 4 standard deviations of the expected count
    assert abs(kept - total * (1 - drop)) < 4 * np.sqrt(total * drop * (1 - drop))


def test_kept_boxes_keep_their_confidence_and_move_by_the_jitter() -> None:
    # the confidences are distinct random numbers: each names its box
    original = {float(c): xyxy for b in boxes_of(recording()) for c, xyxy in zip(b.confidence, b.xyxy, strict=True)}
    moves = []
    for boxes in boxes_of(perturbed(0.2, 3.0)):
        assert (boxes.xyxy[:, 2] > boxes.xyxy[:, 0]).all() and (boxes.xyxy[:, 3] > boxes.xyxy[:, 1]).all()
        assert (boxes.xyxy >= 0).all() and (boxes.xyxy[:, [0, 2]] <= SIZE[0]).all() and (boxes.xyxy[:, [1, 3]] <= SIZE[1]).all()
        for confidence, xyxy in zip(boxes.confidence, boxes.xyxy, strict=True):
            moves.append(xyxy - original[float(confidence)])
    away_from_edges = np.array(moves)[:, 2:]  # right and bottom edges: never clipped here
    assert abs(float(away_from_edges.std()) - 3.0) < 0.3 and abs(float(away_from_edges.mean())) < 0.3


def test_copies_are_reproducible_by_seed_and_differ_between_seeds() -> None:
    a, b, c = perturbed(0.1, 2.0, seed=3), perturbed(0.1, 2.0, seed=3), perturbed(0.1, 2.0, seed=4)
    assert all(np.array_equal(x.xyxy, y.xyxy) for x, y in zip(boxes_of(a), boxes_of(b), strict=True))
    assert not all(len(x) == len(y) and np.array_equal(x.xyxy, y.xyxy) for x, y in zip(boxes_of(a), boxes_of(c), strict=True))


@pytest.mark.parametrize(("drop", "jitter_px", "message"), [
    (1.0, 2.0, "drop must be a probability"),
    (-0.1, 2.0, "drop must be a probability"),
    (0.05, -1.0, "jitter_px must be a number of pixels >= 0"),
    (0.05, float("nan"), "jitter_px must be a number of pixels >= 0"),
])
def test_impossible_perturbations_are_refused(drop: float, jitter_px: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        BoxPerturbation(drop, jitter_px)


def test_unperturbed_copies_score_as_the_recording_and_perturbed_ones_spread(tmp_path: Path) -> None:
    write_recording(walkers(0.7), tmp_path)
    site = load_site(tmp_path / "site.json")
    recorded = read_detections(tmp_path / "detections", {c.id: c.image_size for c in site.cameras})
    truth = read_truth(tmp_path / "truth.txt")
    itself = replay_tracking(site, recorded, truth, WILDTRACK_FPS).headline()
    same = perturbed_replays(site, recorded, truth, WILDTRACK_FPS, runs=2, perturbation=BoxPerturbation(0.0, 0.0))
    assert set(same.scores) == set(SCORED) and same.runs == 2
    for key, spread in same.scores.items():
        assert spread.mean == spread.low == spread.high == pytest.approx(itself[key], nan_ok=True)
    lossy = perturbed_replays(site, recorded, truth, WILDTRACK_FPS, runs=3, perturbation=BoxPerturbation(0.5, 0.0))
    recall = lossy.scores["recall"]
    assert recall.low <= recall.mean <= recall.high and recall.high < itself["recall"]
    assert lossy.as_dict()["recall"] == {"mean": recall.mean, "min": recall.low, "max": recall.high}
    assert lossy.as_dict()["drop"] == 0.5 and lossy.as_dict()["runs"] == 3
    with pytest.raises(ValueError, match="runs must be >= 1"):
        perturbed_replays(site, recorded, truth, WILDTRACK_FPS, runs=0)
