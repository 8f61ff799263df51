from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bevflow.datasets.mot import LONGEST_EMPTY_S, RecordingError, check_no_long_gap, read_detections, read_truth

CAMERAS = {"a": (100, 50), "b": (100, 50)}


def write(folder: Path, files: dict[str, str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (folder / name).write_text(text)
    return folder


def test_boxes_by_camera_and_frame_with_confidence(tmp_path: Path) -> None:
    folder = write(tmp_path / "d", {
        "a.txt": "1,-1,10,5,20,30,0.9,-1,-1,-1\n1,-1,40,5,10,10,0.3,-1,-1,-1\n\n3,-1,0,0,5,5,1.0\n",
        "b.txt": "2,-1,1.5,2.5,3,4,0.75\n",
        "c.txt": "not a camera of the site: not read\n",
    })
    rec = read_detections(folder, CAMERAS)
    assert rec.camera_ids == ("a", "b") and rec.frame_numbers == (1, 2, 3)
    a, b = rec.cameras
    np.testing.assert_array_equal(a.boxes(1).xyxy, [[10, 5, 30, 35], [40, 5, 50, 15]])
    np.testing.assert_array_equal(a.boxes(1).confidence, [0.9, 0.3])
    np.testing.assert_array_equal(b.boxes(2).xyxy, [[1.5, 2.5, 4.5, 6.5]])
    assert len(a.boxes(2)) == 0 and len(b.boxes(7)) == 0
    np.testing.assert_array_equal(a.boxes(1, min_confidence=0.5).confidence, [0.9])
    assert len(b.boxes(2, min_confidence=0.75)) == 1 and len(b.boxes(2, min_confidence=0.8)) == 0


@pytest.mark.parametrize(
    ("row", "expected"),
    [
        ("1,-1,-10,-5,30,20,0.9", [[0, 0, 20, 15]]),  # cut at the top-left corner
        ("1,-1,90,40,30,20,0.9", [[90, 40, 100, 50]]),  # cut at the bottom-right corner
        ("1,-1,120,10,30,20,0.9", None),  # wholly off the image: dropped
    ],
)
def test_boxes_are_clipped_to_the_image_as_a_detectors_are(tmp_path: Path, row: str, expected) -> None:
    folder = write(tmp_path / "d", {"a.txt": row + "\n", "b.txt": ""})
    boxes = read_detections(folder, CAMERAS).cameras[0].boxes(1)
    if expected is None:
        assert len(boxes) == 0
    else:
        np.testing.assert_array_equal(boxes.xyxy, expected)


@pytest.mark.parametrize(
    ("second", "kept"),
    [
        ("0,4,20,40", [[0, 4, 20, 44]]),  # IoU 0.82: one person boxed twice, the more confident kept
        ("0,0,20,20", [[0, 0, 20, 40], [0, 0, 20, 20]]),  # IoU 0.5 exactly: two people, in file order
        ("10,0,20,40", [[0, 0, 20, 40], [10, 0, 30, 40]]),  # IoU 0.33: side by side
    ],
)
def test_a_box_overlapping_a_more_confident_one_as_one_persons_would_is_left_out(tmp_path: Path, second: str, kept) -> None:
    folder = write(tmp_path / "d", {"a.txt": f"1,-1,0,0,20,40,0.6\n1,-1,{second},0.9\n", "b.txt": ""})
    np.testing.assert_array_equal(read_detections(folder, CAMERAS).cameras[0].boxes(1).xyxy, kept)


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("1,-1,10,5,20", r"a\.txt:2: expected at least 7 comma-separated values, got 5"),
        ("1,-1,10,5,20,x,0.9", r"a\.txt:2: 'x' is not a number"),
        ("1,-1,10,5,20,nan,0.9", r"a\.txt:2: 'nan' is not a finite number"),
        ("1.5,-1,10,5,20,30,0.9", r"a\.txt:2: the frame number must be a whole number"),
        ("-1,-1,10,5,20,30,0.9", r"a\.txt:2: frame numbers start at 0"),
        ("1,-1,10,5,0,30,0.9", r"a\.txt:2: a box needs width and height above 0"),
    ],
)
def test_a_bad_detection_row_names_file_and_line(tmp_path: Path, row: str, message: str) -> None:
    folder = write(tmp_path / "d", {"a.txt": "1,-1,10,5,20,30,0.9\n" + row + "\n", "b.txt": ""})
    with pytest.raises(RecordingError, match=message):
        read_detections(folder, CAMERAS)


def test_a_missing_camera_file_names_the_camera(tmp_path: Path) -> None:
    folder = write(tmp_path / "d", {"a.txt": ""})
    with pytest.raises(RecordingError, match=r"b\.txt: no detections file for camera 'b'"):
        read_detections(folder, CAMERAS)


def test_a_missing_folder_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such folder"):
        read_detections(tmp_path / "nowhere", CAMERAS)


def test_truth_by_frame(tmp_path: Path) -> None:
    path = tmp_path / "truth.txt"
    path.write_text("1,7,2.0,0.5\n1,8,3.0,1.5\n3,7,2.1,0.5\n")
    truth = read_truth(path)
    assert truth.frame_numbers == (1, 3)
    ids, xy = truth.at(1)
    assert ids.tolist() == [7, 8] and xy.tolist() == [[2.0, 0.5], [3.0, 1.5]]
    ids, xy = truth.at(2)
    assert ids.shape == (0,) and xy.shape == (0, 2)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1,7,2.0\n", r"truth\.txt:1: expected at least 4"),
        ("1,7,2.0,0.5\n1,7,2.0,0.6\n", r"truth\.txt:2: person 7 appears twice in frame 1"),
        ("1,7.5,2.0,0.5\n", r"truth\.txt:1: the person id must be a whole number"),
        ("1,7,inf,0.5\n", r"truth\.txt:1: 'inf' is not a finite number"),
    ],
)
def test_bad_truth_names_file_and_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "truth.txt"
    path.write_text(text)
    with pytest.raises(RecordingError, match=message):
        read_truth(path)


def test_missing_truth_file(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such file"):
        read_truth(tmp_path / "truth.txt")


HOUR_AT_4_FPS = int(LONGEST_EMPTY_S * 4)


@pytest.mark.parametrize(
    ("frames_of", "message"),
    [
        ({"a.txt": {1, 2, 3}, "the truth": {1, 3}}, None),
        ({"a.txt": {1}, "the truth": {2 + HOUR_AT_4_FPS}}, None),  # an hour without a row: still a recording
        ({"a.txt": {1}, "the truth": {3 + HOUR_AT_4_FPS}},
         rf"frames 2\.\.{2 + HOUR_AT_4_FPS} hold no row at all, 1\.0 hours at 4 fps, between frame 1 \(a\.txt\) "
         rf"and frame {3 + HOUR_AT_4_FPS} \(the truth\)"),
        ({"a.txt": {1, 5}, "b.txt": {5, 10**9}, "the truth": {1, 5}},
         r"frames 6\.\.999999999 hold no row at all, 69,444\.4 hours at 4 fps, between frame 5 \(a\.txt, b\.txt, the truth\) "
         r"and frame 1000000000 \(b\.txt\)"),
        ({"a.txt": set(), "the truth": {10**9}}, None),  # one frame: nothing to step through
    ],
)
def test_an_hour_without_a_row_is_a_frame_number_typed_wrong(frames_of: dict[str, set[int]], message: str | None) -> None:
    if message is None:
        check_no_long_gap(frames_of, 4.0)
        return
    with pytest.raises(RecordingError, match=message):
        check_no_long_gap(frames_of, 4.0)
