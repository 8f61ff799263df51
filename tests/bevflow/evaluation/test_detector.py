from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.detect.coco import write_coco
from bevflow.detections import Boxes
from bevflow.evaluation.detector import evaluate_detector, iou_matrix, match_image, score_boxes

A = [0.0, 0.0, 10.0, 10.0]
B = [20.0, 0.0, 30.0, 10.0]
FAR = [100.0, 100.0, 110.0, 110.0]


@pytest.mark.parametrize(
    ("a", "b", "expected"),
    [(A, A, 1.0), (A, B, 0.0), (A, [5.0, 0.0, 15.0, 10.0], 1 / 3), (A, [0.0, 0.0, 5.0, 10.0], 0.5),
     (A, [2.0, 2.0, 4.0, 4.0], 4 / 100)],
)
def test_iou(a, b, expected) -> None:  # noqa: ANN001
    assert iou_matrix(np.array([a]), np.array([b]))[0, 0] == pytest.approx(expected)


def test_duplicates_count_as_false_positives() -> None:
    tp = match_image(np.array([A, A, B]), np.array([0.9, 0.8, 0.7]), np.array([A, B]))
    assert tp.tolist() == [True, False, True]


@pytest.mark.parametrize(
    ("dets", "scores", "truth", "ap", "p", "r", "f1"),
    [
        # perfect
        ([[A, B]], [[0.9, 0.8]], [[A, B]], 1.0, 1.0, 1.0, 1.0),
        # one miss: recall 1/2, AP 1/2
        ([[A]], [[0.9]], [[A, B]], 0.5, 1.0, 0.5, 2 / 3),
        # a false positive ranked first: precision 1/2 then 2/3; AP = 0.5 * (2/3) + 0.5 * (2/3)
        ([[FAR, A, B]], [[0.9, 0.8, 0.7]], [[A, B]], 2 / 3, 2 / 3, 1.0, 0.8),
        # a false positive ranked last: best F1 cuts it off
        ([[A, B, FAR]], [[0.9, 0.8, 0.1]], [[A, B]], 1.0, 1.0, 1.0, 1.0),
        # two images, one empty of people
        ([[A], [FAR]], [[0.9], [0.95]], [[A], []], 0.5, 0.5, 1.0, 2 / 3),
    ],
)
def test_scores(dets, scores, truth, ap, p, r, f1) -> None:  # noqa: ANN001
    s = score_boxes([np.array(d, float).reshape(-1, 4) for d in dets], [np.array(x, float) for x in scores],
                    [np.array(t, float).reshape(-1, 4) for t in truth])  # fmt: skip
    assert (s.AP50, s.precision, s.recall, s.F1) == pytest.approx((ap, p, r, f1))
    assert s.images == len(truth) and s.annotations == sum(len(t) for t in truth)


CROWD = [40.0, 0.0, 80.0, 20.0]  # a crowd region (COCO iscrowd 1)
IN_CROWD = [45.0, 2.0, 55.0, 12.0]  # a detection wholly inside it
HALF_IN = [75.0, 0.0, 85.0, 10.0]  # half its area inside it


@pytest.mark.parametrize(
    ("dets", "scores", "truth", "ap", "p", "r"),
    [
        # a detection in the crowd ranked first: neither right nor wrong
        ([IN_CROWD, A, B], [0.9, 0.8, 0.7], [A, B], 1.0, 1.0, 1.0),
        # half inside still counts for nothing (COCO's rule: at least half its area)
        ([HALF_IN, A, B], [0.9, 0.8, 0.7], [A, B], 1.0, 1.0, 1.0),
        # a person boxed inside the crowd region is found as any other
        ([IN_CROWD, A], [0.9, 0.8], [IN_CROWD, A], 1.0, 1.0, 1.0),
        # one box over the whole crowd counts for nothing either
        ([CROWD, A], [0.9, 0.8], [A], 1.0, 1.0, 1.0),
        # outside the region a false positive stays one
        ([FAR, A, B], [0.9, 0.8, 0.7], [A, B], 2 / 3, 2 / 3, 1.0),
    ],
)
def test_crowd_regions_count_for_nothing(dets, scores, truth, ap, p, r) -> None:  # noqa: ANN001
    s = score_boxes([np.array(dets, float)], [np.array(scores, float)], [np.array(truth, float)], crowd=[np.array([CROWD])])
    assert (s.AP50, s.AP50_rotated, s.precision, s.recall) == pytest.approx((ap, ap, p, r))
    assert s.annotations == len(truth) and s.detections == len(dets)


def test_without_crowd_regions_a_detection_there_is_wrong() -> None:
    s = score_boxes([np.array([IN_CROWD, A, B])], [np.array([0.9, 0.8, 0.7])], [np.array([A, B])])
    assert s.AP50 == pytest.approx(2 / 3)


def test_no_detections_scores_zero() -> None:
    s = score_boxes([np.zeros((0, 4))], [np.zeros(0)], [np.array([A])])
    assert (s.AP50, s.precision, s.recall, s.F1) == (0.0, 0.0, 0.0, 0.0)


def test_mismatched_inputs_raise() -> None:
    with pytest.raises(ValueError, match="one entry per image"):
        score_boxes([np.zeros((0, 4))], [], [np.zeros((0, 4))])


class _Oracle:
    """Returns the annotated boxes of each image (looked up by its size), remembering the calls."""

    def __init__(self, boxes: dict[tuple[int, int], np.ndarray]) -> None:
        self.boxes, self.calls = boxes, []

    def detect(self, image, camera_height_m, focal_px):  # noqa: ANN001, ANN201
        self.calls.append(("detect", camera_height_m, focal_px))
        return Boxes(self.boxes[image.shape[:2]])

    def detect_scaled(self, image, scale=1.0):  # noqa: ANN001, ANN201
        self.calls.append(("scaled", scale))
        return Boxes(self.boxes[image.shape[:2]])


def test_evaluate_detector_reads_images_and_scaling_keys(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((40, 50, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((30, 60, 3), np.uint8))
    truth = [np.array([A]), np.array([B, FAR])]
    write_coco(tmp_path / "ann.json", [{"file_name": "a.png", "camera_height_m": 3.3, "focal_px": 200.0}, {"file_name": "b.png"}], truth)
    oracle = _Oracle({(40, 50): truth[0], (30, 60): truth[1]})
    s = evaluate_detector(oracle, tmp_path / "ann.json", scale=0.5)
    assert s.AP50 == pytest.approx(1.0) and s.annotations == 3 and s.images == 2
    assert s.AP50_rotated == s.AP50  # axis-aligned annotations: the same boxes at 0°
    assert oracle.calls == [("detect", 3.3, 200.0), ("scaled", 0.5)]
    assert s.ms_per_frame is not None and s.ms_per_frame >= 0


def test_a_crowd_annotation_is_nobody_to_find_and_hides_no_false_positive(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((40, 50, 3), np.uint8))
    doc = {"images": [{"id": 1, "file_name": "a.png"}], "categories": [{"id": 1, "name": "person"}],
           "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 10, 10]},
                           {"id": 2, "image_id": 1, "category_id": 1, "bbox": [40, 0, 40, 20], "iscrowd": 1}]}  # fmt: skip
    (tmp_path / "ann.json").write_text(json.dumps(doc))
    s = evaluate_detector(_Oracle({(40, 50): np.array([IN_CROWD, A])}), tmp_path / "ann.json", scale=1.0)
    assert (s.annotations, s.detections, s.AP50, s.precision, s.recall) == (1, 2, 1.0, 1.0, 1.0)


def test_evaluate_detector_reports_missing_images(tmp_path: Path) -> None:
    write_coco(tmp_path / "ann.json", [{"file_name": "gone.png"}], [np.zeros((0, 4))])
    with pytest.raises(FileNotFoundError, match="gone.png"):
        evaluate_detector(_Oracle({}), tmp_path / "ann.json")
