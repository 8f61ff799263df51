"""The INT8 copy of a detector: quantised operators, the input scale carried over, and the same
people found as by the float32 original, for a fresh copy and for the shipped one."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest

from bevflow.detect.coco import read_coco
from bevflow.detect.runtime import DEFAULT_MODEL, INT8_MODEL, LOW_CEILING_MODEL, Detector
from bevflow.evaluation.detector import iou_matrix
from bevflow.training.dataset import render_evaluation_set

onnx = pytest.importorskip("onnx")

from bevflow.training.quantize import quantize_detector  # noqa: E402  # after the skip: it needs onnx


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_evaluation_set(tmp_path_factory.mktemp("frames"), 3, seed=77)


def matched_share(a: Detector, b: Detector, annotations: Path) -> float:
    """Of ``a``'s boxes on the frames, the share that ``b`` also gives (IoU >= 0.7)."""
    found = matched = 0
    for frame in read_coco(annotations):
        image = cv2.imread(str(frame.path))
        assert frame.camera_height_m is not None and frame.focal_px is not None
        boxes_a = a.detect(image, frame.camera_height_m, frame.focal_px).xyxy
        boxes_b = b.detect(image, frame.camera_height_m, frame.focal_px).xyxy
        found += len(boxes_a)
        if len(boxes_a) and len(boxes_b):
            matched += int((iou_matrix(boxes_a, boxes_b).max(axis=1) >= 0.7).sum())
    assert found > 0, "the frames showed nobody: nothing compared"
    return matched / found


def test_a_quantised_copy_has_integer_convolutions_the_same_scale_and_finds_the_same_people(frames: Path, tmp_path: Path) -> None:
    out = quantize_detector(LOW_CEILING_MODEL, read_coco(frames)[:2], tmp_path / "low-int8.onnx")
    ops = {node.op_type for node in onnx.load(str(out)).graph.node}
    assert {"QuantizeLinear", "DequantizeLinear", "Conv"} <= ops
    original, copy = Detector(LOW_CEILING_MODEL, threads=1), Detector(out, threads=1)
    assert copy.zoom == original.zoom == pytest.approx(1.2)  # the metadata came along
    assert matched_share(original, copy, frames) >= 0.9


def test_the_shipped_int8_model_finds_what_the_general_model_finds(frames: Path) -> None:
    assert matched_share(Detector(DEFAULT_MODEL, threads=1), Detector(INT8_MODEL, threads=1), frames) >= 0.9


def test_calibration_needs_frames(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="at least one frame"):
        quantize_detector(DEFAULT_MODEL, [], tmp_path / "x.onnx")
    assert not list(tmp_path.glob("*.onnx"))
