"""``AP50_rotated`` (rotated IoU, as CEPDOF / RAPiD score), how frames without calibration are fed
to the detector, and the pictures of ``--draw``."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.detect.coco import read_coco, rotated_to_xyxy
from bevflow.detect.rotated import outline_xyxy, radial_angle, rotated_iou_matrix
from bevflow.detections import Boxes
from bevflow.evaluation.detector import detect_frames, detect_turned_frames, evaluate_detector, frame_setup, score_boxes, score_frames
from bevflow.evaluation.drawing import HIT, MISS, TRUTH, UNJUDGED, write_drawings

SQUARE = np.array([[0.0, 0.0, 10.0, 10.0]])


# Hand-computed IoUs: two w × L strips crossing at angle φ share a rhombus of area w² / sin φ.
@pytest.mark.parametrize(
    ("det", "truth", "iou"),
    [
        ([[5, 5, 10, 10, 0]], [[5, 5, 10, 10, 0]], 1.0),
        ([[5, 5, 10, 10, 45]], [[5, 5, 10, 10, 0]], 0.7071),  # 100 (2√2 − 2) / (200 − that)
        ([[5, 5, 4, 20, 90]], [[5, 5, 4, 20, 0]], 16 / 144),  # a cross
        ([[5, 5, 4, 20, 30]], [[5, 5, 4, 20, 0]], 32 / 128),  # rhombus 16 / sin 30°
        ([[5, 5, 4, 20, 45]], [[5, 5, 4, 20, 0]], 22.627 / 137.373),  # rhombus 16 / sin 45°
        ([[5 + 6, 5, 4, 20, 90]], [[5, 5, 4, 20, 90]], 56 / 104),  # 6 along its length apart: a match
        ([[5 + 7, 5, 4, 20, 90]], [[5, 5, 4, 20, 90]], 52 / 108),  # a little further: not
    ],
)
def test_rotated_ap_uses_rotated_iou(det: list, truth: list, iou: float) -> None:
    d, t = np.array(det, float), np.array(truth, float)
    s = score_boxes([rotated_to_xyxy(d)], [np.array([0.9])], [rotated_to_xyxy(t)], rotated_detections=[d], rotated_truth=[t])
    assert rotated_iou_matrix(d, t)[0, 0] == pytest.approx(iou, abs=1e-4)
    assert s.AP50_rotated == (1.0 if iou >= 0.5 else 0.0)


def test_without_rotated_boxes_rotated_ap_is_ap50() -> None:
    s = score_boxes([SQUARE], [np.array([0.5])], [SQUARE + 3])
    assert s.AP50_rotated == s.AP50


def _rotated_set(tmp_path: Path, people: list[list[float]], size: int = 200) -> Path:
    frame = np.zeros((size, size, 3), np.uint8)
    cv2.circle(frame, (size // 2, size // 2), size // 2 - 10, (120, 140, 160), -1)
    cv2.imwrite(str(tmp_path / "f.png"), frame)
    doc = {"images": [{"id": 1, "file_name": "f.png"}], "categories": [{"id": 1, "name": "person"}],
           "annotations": [{"id": k, "image_id": 1, "category_id": 1, "bbox": b} for k, b in enumerate(people)]}
    (tmp_path / "ann.json").write_text(json.dumps(doc))
    return tmp_path / "ann.json"


class _Enclosing:
    """An upright detector that finds each annotated person by their enclosing box."""

    def __init__(self, rotated: np.ndarray) -> None:
        self.rotated, self.calls = rotated, []

    def detect(self, image, camera_height_m, focal_px):  # noqa: ANN001, ANN201
        self.calls.append((camera_height_m, focal_px))
        return Boxes(rotated_to_xyxy(self.rotated), np.full(len(self.rotated), 0.8))


def test_upright_boxes_of_radial_people_score_by_their_radial_angle(tmp_path: Path) -> None:
    centre = (99.5, 99.5)
    people = []
    for x, y in [(60.0, 150.0), (150.0, 60.0), (40.0, 90.0)]:  # people lying along the radius
        people.append([x, y, 12.0, 30.0, float(radial_angle(np.array([x]), np.array([y]), centre)[0])])
    ann = _rotated_set(tmp_path, people)
    detector = _Enclosing(np.array(people))
    s = evaluate_detector(detector, ann)
    assert s.AP50_rotated == pytest.approx(1.0) and s.annotations == 3
    assert len(detector.calls) == 1 and detector.calls[0][0] == 3.0  # assumed: a 3 m ceiling


def test_a_detector_with_angles_is_scored_by_them(tmp_path: Path) -> None:
    person = [100.0, 160.0, 12.0, 30.0, 45.0]  # not radial: seated at 45° to the radius
    ann = _rotated_set(tmp_path, [person])

    class Rotating:
        def detect_boxes(self, image, camera_height_m, focal_px, centre):  # noqa: ANN001, ANN201
            return Boxes(outline_xyxy(np.array([person])), [0.7]), np.array([person])

    assert evaluate_detector(Rotating(), ann).AP50_rotated == pytest.approx(1.0)
    assert evaluate_detector(_Enclosing(np.array([person])), ann).AP50_rotated == 0.0  # turned radially: wrong


class _Upright:
    """An upright detector that gives the boxes it is made with."""

    def __init__(self, xyxy: np.ndarray) -> None:
        self.xyxy = xyxy

    def detect(self, image, camera_height_m, focal_px):  # noqa: ANN001, ANN201
        return Boxes(self.xyxy, np.full(len(self.xyxy), 0.8))


@pytest.mark.parametrize(
    ("side_factor", "ap50"),
    [
        (1.0, 1.0),  # the outline itself
        (800**0.5 / 500**0.5, 1.0),  # the enclosing rectangle: IoU 500 / 800 with the outline
        (1.15 * 800**0.5 / 500**0.5, 0.0),  # a little larger: IoU 0.47 with the outline, 0.76 with the rectangle
    ],
)
def test_rotated_truth_counts_as_its_outline_for_ap50(tmp_path: Path, side_factor: float, ap50: float) -> None:
    person = [100.0, 150.0, 10.0, 30.0, 45.0]  # outline 22.4 px square, enclosing rectangle 28.3 px
    ann = _rotated_set(tmp_path, [person])
    half = side_factor * 500**0.5 / 2
    s = evaluate_detector(_Upright(np.array([[100 - half, 150 - half, 100 + half, 150 + half]])), ann)
    assert s.AP50 == pytest.approx(ap50)
    [result], _ = detect_frames(_Upright(np.zeros((0, 4))), ann)
    assert np.allclose(result.truth_xyxy, outline_xyxy(np.array([person])))


@pytest.mark.parametrize(
    ("keys", "height", "focal", "scale", "expected"),
    [
        ({"camera_height_m": 4.0, "focal_px": 300.0}, 3.3, 200.0, 0.5, (4.0, 300.0, None, False)),  # the image's own keys
        ({}, 3.3, 200.0, 0.5, (3.3, 200.0, None, False)),  # then the caller's calibration
        ({}, None, None, 0.5, (None, None, 0.5, False)),  # then the caller's scale
        ({}, None, None, None, (3.0, None, None, True)),  # then what the frame suggests
    ],
)
def test_frame_setup_precedence(tmp_path: Path, keys: dict, height: float | None, focal: float | None, scale: float | None,
                                expected: tuple) -> None:  # fmt: skip
    ann = _rotated_set(tmp_path, [])
    doc = json.loads(ann.read_text())
    doc["images"][0].update(keys)
    ann.write_text(json.dumps(doc))
    entry = read_coco(ann)[0]
    image = cv2.imread(str(entry.path))
    setup = frame_setup(entry, image, height, focal, scale)
    h, f, sc, assumed = expected
    assert setup.camera_height_m == h and setup.scale == sc and (setup.assumed is not None) == assumed
    if f is not None:
        assert setup.focal_px == f
    if assumed:  # a 180-px circle of a 190° lens
        assert setup.focal_px == pytest.approx(90 / np.radians(95), rel=0.03)
        assert setup.centre == pytest.approx((99.5, 99.5), abs=1.0)


def test_drawings_show_truth_and_detections(tmp_path: Path) -> None:
    person = [60.0, 150.0, 12.0, 30.0, float(radial_angle(np.array([60.0]), np.array([150.0]), (99.5, 99.5))[0])]
    ann = _rotated_set(tmp_path, [person])

    class TwoBoxes:
        def detect(self, image, camera_height_m, focal_px):  # noqa: ANN001, ANN201
            return Boxes(np.r_[rotated_to_xyxy(np.array([person])), [[120.0, 40.0, 140.0, 60.0]]], np.array([0.9, 0.8]))

    results, _ = detect_frames(TwoBoxes(), ann, log=lambda m: None)
    written = write_drawings(results, tmp_path / "drawn", score_frames(results).threshold)
    assert [p.name for p in written] == ["f.jpg"]
    picture = cv2.imread(str(written[0])).astype(int)
    b, g, r = picture[..., 0], picture[..., 1], picture[..., 2]
    assert ((g > 150) & (r < 140) & (b < 140)).any()  # the truth, green (JPEG shifts colours a little)
    assert ((r > 150) & (g > 150) & (b < 110)).any()  # the matched detection, yellow
    assert not ((r > 150) & (g < 110) & (b < 110)).any()  # the other scored below the threshold: not drawn
    assert (TRUTH, HIT, MISS) == ((80, 220, 80), (0, 220, 255), (40, 40, 255))


def test_frames_nobody_annotated_are_run_and_drawn_unjudged(tmp_path: Path) -> None:
    images = _rotated_set(tmp_path, []).parent  # the frame f.png and its annotations, which are not read

    class OneBox:
        def detect(self, image, camera_height_m, focal_px):  # noqa: ANN001, ANN201
            return Boxes(np.array([[120.0, 40.0, 140.0, 70.0]]), np.array([0.9]))

    [(results, _)] = detect_turned_frames(OneBox(), None, [0.0], images, log=lambda m: None)
    assert [r.entry.path.name for r in results] == ["f.png"] and not results[0].entry.annotated
    [written] = write_drawings(results, tmp_path / "drawn", 0.5)
    picture = cv2.imread(str(written)).astype(int)
    b, g, r = picture[..., 0], picture[..., 1], picture[..., 2]
    assert ((b > 200) & (g > 110) & (g < 210) & (r < 100)).any()  # the detection, blue: nothing to judge it by
    assert not ((r > 150) & (b < 110)).any()  # neither yellow (right) nor red (wrong)
    assert UNJUDGED == (255, 160, 40)
    with pytest.raises(ValueError, match="give the annotations, the images' folder, or both"):
        detect_turned_frames(OneBox(), None, [0.0])
