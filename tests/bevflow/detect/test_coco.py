from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bevflow.detect.coco import CocoError, read_coco, rotated_to_xyxy, unannotated_images, write_coco


@pytest.mark.parametrize(
    ("rotated", "expected"),
    [
        ([10, 20, 4, 8, 0], [8, 16, 12, 24]),
        ([10, 20, 4, 8, 90], [6, 18, 14, 22]),
        ([0, 0, 2, 2, 45], [-np.sqrt(2), -np.sqrt(2), np.sqrt(2), np.sqrt(2)]),
    ],
)
def test_rotated_to_xyxy(rotated, expected) -> None:  # noqa: ANN001
    np.testing.assert_allclose(rotated_to_xyxy(np.array([rotated], float)), [expected], atol=1e-9)


def _write(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "ann.json"
    path.write_text(json.dumps(doc))
    return path


def test_reads_axis_aligned_and_rotated_person_boxes(tmp_path: Path) -> None:
    doc = {
        "images": [{"id": 7, "file_name": "a.jpg", "camera_height_m": 3.3, "focal_px": 300.0}, {"id": 8, "file_name": "b.jpg"}],
        "annotations": [
            {"id": 1, "image_id": 7, "category_id": 1, "bbox": [10, 20, 4, 8]},
            {"id": 2, "image_id": 7, "category_id": 1, "bbox": [50, 60, 4, 8, 90]},
            {"id": 3, "image_id": 7, "category_id": 2, "bbox": [0, 0, 1, 1]},
        ],
        "categories": [{"id": 1, "name": "person"}, {"id": 2, "name": "chair"}],
    }
    images = read_coco(_write(tmp_path, doc))
    assert [im.path.name for im in images] == ["a.jpg", "b.jpg"]
    np.testing.assert_allclose(images[0].xyxy, [[10, 20, 14, 28], [46, 58, 54, 62]])
    assert images[0].camera_height_m == 3.3 and images[0].focal_px == 300.0
    assert len(images[1].rotated) == 0 and images[1].camera_height_m is None


def test_crowd_regions_are_read_apart_from_people(tmp_path: Path) -> None:
    doc = {
        "images": [{"id": 7, "file_name": "a.jpg"}, {"id": 8, "file_name": "b.jpg"}],
        "annotations": [
            {"id": 1, "image_id": 7, "bbox": [10, 20, 4, 8], "iscrowd": 0},
            {"id": 2, "image_id": 7, "bbox": [30, 30, 40, 20], "iscrowd": 1},
            {"id": 3, "image_id": 8, "bbox": [5, 5, 10, 10, 90], "iscrowd": True},
        ],
    }
    a, b = read_coco(_write(tmp_path, doc))
    np.testing.assert_allclose(a.xyxy, [[10, 20, 14, 28]])
    np.testing.assert_allclose(a.crowd_xyxy, [[30, 30, 70, 50]])
    assert len(b.rotated) == 0 and b.crowd.tolist() == [[5, 5, 10, 10, 90]]


def test_write_then_read_round_trip(tmp_path: Path) -> None:
    boxes = [np.array([[1.0, 2.0, 11.0, 22.0]]), np.zeros((0, 4))]
    write_coco(tmp_path / "c.json", [{"file_name": "x.png", "width": 5, "height": 5}, {"file_name": "y.png"}], boxes)
    images = read_coco(tmp_path / "c.json", images_dir=tmp_path / "imgs")
    np.testing.assert_allclose(images[0].xyxy, boxes[0])
    assert images[0].path == tmp_path / "imgs" / "x.png"


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ([], "not a COCO file"),
        ({"images": []}, "not a COCO file"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "image_id": 1, "bbox": [1, 2, 3]}]},
         r"annotations\[0\]\.bbox: List should have at least 4 items"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "image_id": 1, "bbox": [1, 2, 3, 4, 5, 6]}]},
         r"annotations\[0\]\.bbox: List should have at most 5 items"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 7, "image_id": 9, "bbox": [1, 2, 3, 4]}]},
         "annotation 7 refers to unknown image 9"),
        ({"images": [{"id": 1}], "annotations": []}, r"images\[0\]\.file_name: Field required"),
        ({"images": [1], "annotations": []}, r"images\[0\]: should be a JSON object"),
        ({"images": "x", "annotations": []}, "images: Input should be a valid list"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "image_id": 1}]}, r"annotations\[0\]\.bbox: Field required"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "bbox": [1, 2, 3, 4]}]}, r"annotations\[0\]\.image_id: Field required"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "image_id": 1, "bbox": [1, 2, "x", 4]}]},
         r"annotations\[0\]\.bbox\[2\]: Input should be a valid number"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "image_id": 1, "bbox": [1, 2, float("nan"), 4]}]},
         r"annotations\[0\]\.bbox\[2\]: Input should be a finite number"),
        ({"images": [{"id": 1, "file_name": "a", "camera_height_m": "high"}], "annotations": []},
         r"images\[0\]\.camera_height_m: Input should be a valid number"),
        ({"images": [{"id": 1, "file_name": "a", "focal_px": -3}], "annotations": []}, r"images\[0\]\.focal_px: Input should be greater than 0"),
        ({"images": [{"id": 1}, {"id": 2}], "annotations": []}, r"images\[0\]\.file_name: Field required \(and 1 more\)"),
        ({"images": [{"id": 1, "file_name": "a"}], "annotations": [{"id": 1, "image_id": 1, "bbox": [1, 2, 3, 4], "iscrowd": 2}]},
         r"annotations\[0\]\.iscrowd: Input should be less than or equal to 1"),
    ],
)
def test_bad_files_say_why(tmp_path: Path, doc, message: str) -> None:  # noqa: ANN001
    with pytest.raises(CocoError, match=message):
        read_coco(_write(tmp_path, doc))


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CocoError, match="cannot read"):
        read_coco(tmp_path / "nope.json")


@pytest.mark.parametrize(
    ("files", "found"),
    [
        (["b.jpg", "a.PNG", "notes.txt", "c.jpeg", "d.webp"], ["a.PNG", "b.jpg", "c.jpeg", "d.webp"]),
        (["frame.tiff", "frame.bmp"], ["frame.bmp", "frame.tiff"]),
        (["notes.txt"], None),
        ([], None),
    ],
)
def test_a_folder_of_frames_nobody_annotated(tmp_path: Path, files: list[str], found: list[str] | None) -> None:
    for name in files:
        (tmp_path / name).write_bytes(b"")
    if found is None:
        with pytest.raises(CocoError, match="holds no image"):
            unannotated_images(tmp_path)
        return
    entries = unannotated_images(tmp_path)
    assert [e.path.name for e in entries] == found
    assert all(not e.annotated and e.rotated.shape == (0, 5) for e in entries)


def test_unannotated_images_needs_a_folder(tmp_path: Path) -> None:
    with pytest.raises(CocoError, match="is not a folder"):
        unannotated_images(tmp_path / "nope")
