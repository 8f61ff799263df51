"""Frames and their truth turned about the image circle's centre, as a camera turned on its mount
would see them, and the spread of scores over the turns."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.detect.coco import CocoImage
from bevflow.detect.rotated import rotated_corners
from bevflow.evaluation.turned import TurnedScores, turn_angles, turned

CENTRE = (99.5, 99.5)


def _frame(boxes: list[list[float]]) -> tuple[CocoImage, np.ndarray]:
    image = np.zeros((200, 200, 3), np.uint8)
    for corners in rotated_corners(np.array(boxes)):
        cv2.fillPoly(image, [np.round(corners).astype(np.int32)], (255, 255, 255))
    return CocoImage(Path("a.jpg"), np.array(boxes, float), oriented=True), image


@pytest.mark.parametrize(
    ("box", "degrees", "expected"),
    [
        ([99.5, 159.5, 20, 50, 0], 90, [159.5, 99.5, 20, 50, -90]),  # below the centre → right of it
        ([99.5, 159.5, 20, 50, 0], -90, [39.5, 99.5, 20, 50, 90]),  # → left of it
        ([99.5, 159.5, 20, 50, 0], 180, [99.5, 39.5, 20, 50, -180]),  # → above it
        ([139.5, 99.5, 20, 50, 30], 45, [99.5 + 40 / 2**0.5, 99.5 - 40 / 2**0.5, 20, 50, -15]),
    ],
)
def test_a_box_turns_with_its_frame(box: list[float], degrees: float, expected: list[float]) -> None:
    entry, image = _frame([box])
    moved, out = turned(entry, image, CENTRE, degrees)
    np.testing.assert_allclose(moved.rotated, [expected], atol=1e-6)
    # The turned frame's pixels lie where the turned box says.
    inside = np.zeros((200, 200), np.uint8)
    cv2.fillPoly(inside, [np.round(rotated_corners(moved.rotated)[0]).astype(np.int32)], 1)
    lit = out.max(axis=2) > 127
    assert (lit & (inside == 1)).sum() > 0.85 * lit.sum()


def test_people_turned_out_of_the_frame_are_dropped() -> None:
    wide = np.zeros((100, 300, 3), np.uint8)  # a frame cut top and bottom
    entry = CocoImage(Path("a.jpg"), np.array([[250.0, 50.0, 10, 20, 0], [150.0, 60.0, 10, 20, 0]]), oriented=True)
    moved, out = turned(entry, wide, (149.5, 49.5), 90)
    assert out.shape == wide.shape
    np.testing.assert_allclose(moved.rotated, [[160.0, 49.0, 10, 20, -90]])  # the other went above the frame


def test_crowd_regions_turn_with_the_people() -> None:
    person, crowd = [99.5, 159.5, 20, 50, 0], [[139.5, 99.5, 40, 30, 0], [99.5, 5.0, 40, 8, 0]]
    entry = CocoImage(Path("a.jpg"), np.array([person]), oriented=True, crowd=np.array(crowd))
    moved, _ = turned(entry, np.zeros((200, 200, 3), np.uint8), CENTRE, 90)
    np.testing.assert_allclose(moved.rotated, [[159.5, 99.5, 20, 50, -90]], atol=1e-6)
    # right of the centre → above it; at the top → at the left
    np.testing.assert_allclose(moved.crowd, [[99.5, 59.5, 40, 30, -90], [5.0, 99.5, 40, 8, -90]], atol=1e-6)


def test_axis_aligned_truth_is_refused() -> None:
    entry, image = _frame([[99.5, 159.5, 20, 50, 0]])
    with pytest.raises(ValueError, match="a.jpg: turning a frame needs rotated truth boxes"):
        turned(CocoImage(entry.path, entry.rotated), image, CENTRE, 30)


@pytest.mark.parametrize(
    ("turns", "degrees"),
    [(1, [0.0]), (2, [0.0, 180.0]), (5, [0.0, 72.0, 144.0, 216.0, 288.0])],
)
def test_turns_spread_round_the_circle(turns: int, degrees: list[float]) -> None:
    assert turn_angles(turns) == degrees
    # Five turns fall every 9 degrees within the rim tiles' 45.
    if turns == 5:
        assert sorted(d % 45 for d in degrees) == [0.0, 9.0, 18.0, 27.0, 36.0]


def test_no_turns_is_refused() -> None:
    with pytest.raises(ValueError, match="turns must be >= 1, got 0"):
        turn_angles(0)


def test_the_spread_of_each_score() -> None:
    scores = [{"AP50": a, "AP50_rotated": a / 2, "precision": 1.0, "recall": 0.5, "F1": 0.6, "images": 3} for a in (0.9, 0.6, 0.6)]
    spread = TurnedScores.of([0.0, 120.0, 240.0], scores)
    assert spread.as_dict()["AP50"] == pytest.approx({"mean": 0.7, "min": 0.6, "max": 0.9})
    assert spread.as_dict()["AP50_rotated"]["max"] == pytest.approx(0.45) and spread.as_dict()["degrees"] == [0.0, 120.0, 240.0]
