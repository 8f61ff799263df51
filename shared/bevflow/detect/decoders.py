"""Turning a detector's raw ONNX outputs into person boxes.

Supported output layouts (``FORMATS``):

- ``centernet``: the project's own model (``bevflow.training.model.DetectorExport``): three
  outputs at stride 4: ``heatmap`` (1, 1, h, w) already sigmoid with non-peaks zeroed,
  ``size`` (1, 2, h, w) box width and height in input pixels, ``offset`` (1, 2, h, w) the centre
  inside its cell.
- ``yolov5``: one output (B, N, 5 + C) rows (cx, cy, w, h, objectness, class scores...), boxes
  in input pixels (YOLOv5 / YOLOv7 exports).
- ``yolov8``: one output (B, 4 + C, N): (cx, cy, w, h, class scores...) per column, no
  objectness (YOLOv8 / YOLO11 exports).
- ``yolox``: one output (B, N, 5 + C) like yolov5 but, as YOLOX's exporter writes by default,
  with centres and sizes still relative to the grid cells of strides 8, 16 and 32
  (``decode_in_inference=False``); they are decoded here.
- ``fastestdet``: one output (B, 5 + C, H, W), one box per grid cell: objectness (after sigmoid),
  centre offsets in the cell (before tanh), width and height as shares of the input (before
  sigmoid), class scores (after softmax), as FastestDet's exporter writes them; a cell's score
  is objectness^0.6 · class^0.4, as FastestDet's own decoding.

Every decoder keeps one class (``person_class``, 0 in COCO), drops scores under the threshold and
returns boxes (N, 4) xyxy and scores (N,) in the model's input pixels; ``bevflow.detections.nms``
then removes duplicates.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
FORMATS = ("centernet", "yolov5", "yolov8", "yolox", "fastestdet")
CENTERNET_STRIDE = 4
YOLOX_STRIDES = (8, 16, 32)


def decode_centernet(
    heatmap: np.ndarray, size: np.ndarray, offset: np.ndarray, score_threshold: float, stride: int = CENTERNET_STRIDE
) -> tuple[FloatArray, FloatArray]:
    """One image's outputs ((1, 1, h, w), (1, 2, h, w), (1, 2, h, w)) → boxes and scores. A
    cell (i, j) covers input pixels [stride·j − 0.5, stride·(j + 1) − 0.5) in pixel-centre
    coordinates, so the centre is stride·(j + offset) − 0.5."""
    heat = np.asarray(heatmap)[0, 0]
    rows, cols = np.nonzero(heat >= score_threshold)
    scores = heat[rows, cols].astype(np.float64)
    off = np.asarray(offset)[0][:, rows, cols].astype(np.float64)
    wh = np.asarray(size)[0][:, rows, cols].astype(np.float64)
    cx = stride * (cols + off[0]) - 0.5
    cy = stride * (rows + off[1]) - 0.5
    xyxy = np.stack([cx - wh[0] / 2, cy - wh[1] / 2, cx + wh[0] / 2, cy + wh[1] / 2], 1)
    return xyxy, scores


def decode_yolov5(output: np.ndarray, score_threshold: float, person_class: int = 0) -> tuple[FloatArray, FloatArray]:
    """One image's (N, 5 + C) rows → boxes and scores (objectness × class score)."""
    rows = np.asarray(output, dtype=np.float64).reshape(-1, np.asarray(output).shape[-1])
    scores = rows[:, 4] * (rows[:, 5 + person_class] if rows.shape[1] > 5 else 1.0)
    if rows.shape[1] > 6:  # keep boxes whose best class is the person
        scores = np.where(rows[:, 5:].argmax(1) == person_class, scores, 0.0)
    keep = scores >= score_threshold
    return _cxcywh_to_xyxy(rows[keep, :4]), scores[keep]


def decode_yolov8(output: np.ndarray, score_threshold: float, person_class: int = 0) -> tuple[FloatArray, FloatArray]:
    """One image's (4 + C, N) columns → boxes and scores (the class score)."""
    cols = np.asarray(output, dtype=np.float64).reshape(np.asarray(output).shape[-2], -1).T
    cls = cols[:, 4:]
    scores = np.where(cls.argmax(1) == person_class, cls[:, person_class], 0.0)
    keep = scores >= score_threshold
    return _cxcywh_to_xyxy(cols[keep, :4]), scores[keep]


def decode_yolox(
    output: np.ndarray, input_hw: tuple[int, int], score_threshold: float, person_class: int = 0, strides: Sequence[int] = YOLOX_STRIDES
) -> tuple[FloatArray, FloatArray]:
    """One image's (N, 5 + C) grid-relative rows → boxes and scores."""
    rows = np.asarray(output, dtype=np.float64).reshape(-1, np.asarray(output).shape[-1]).copy()
    grid, stride = yolox_grid(input_hw, strides)
    if len(grid) != len(rows):
        raise ValueError(f"YOLOX output has {len(rows)} rows; a {input_hw[0]}x{input_hw[1]} input with strides {tuple(strides)} gives {len(grid)}")
    rows[:, :2] = (rows[:, :2] + grid) * stride[:, None]
    rows[:, 2:4] = np.exp(rows[:, 2:4]) * stride[:, None]
    return decode_yolov5(rows, score_threshold, person_class)


def decode_fastestdet(output: np.ndarray, input_hw: tuple[int, int], score_threshold: float, person_class: int = 0) -> tuple[FloatArray, FloatArray]:
    """One image's (5 + C, H, W) grid → boxes and scores in input pixels."""
    out = np.asarray(output, dtype=np.float64)
    gh, gw = out.shape[1:]
    scores = np.clip(out[0], 0, None) ** 0.6 * np.clip(out[5 + person_class], 0, None) ** 0.4
    yy, xx = np.nonzero(scores >= score_threshold)
    reg = out[1:5, yy, xx]
    cx = (xx + np.tanh(reg[0])) / gw * input_hw[1]
    cy = (yy + np.tanh(reg[1])) / gh * input_hw[0]
    w, h = input_hw[1] / (1 + np.exp(-reg[2])), input_hw[0] / (1 + np.exp(-reg[3]))
    return _cxcywh_to_xyxy(np.stack([cx, cy, w, h], 1)), scores[yy, xx]


def yolox_grid(input_hw: tuple[int, int], strides: Sequence[int] = YOLOX_STRIDES) -> tuple[FloatArray, FloatArray]:
    """The (x, y) cell of every YOLOX output row and its stride, in the exporter's order."""
    cells, per_row = [], []
    for s in strides:
        h, w = input_hw[0] // s, input_hw[1] // s
        yy, xx = np.mgrid[0:h, 0:w]
        cells.append(np.stack([xx.ravel(), yy.ravel()], 1))
        per_row.append(np.full(h * w, float(s)))
    return np.concatenate(cells).astype(np.float64), np.concatenate(per_row)


def guess_format(output_shapes: Sequence[Sequence[int | str | None]], input_hw: tuple[int, int]) -> str:
    """The layout of a model's outputs: three outputs are the project's own model; one output
    whose middle axis is shorter than its last is YOLOv8-style; otherwise the row count tells
    YOLOX (one row per cell of strides 8/16/32) from YOLOv5 (three anchors per cell); one output
    shaped like an image (B, C, H, W) is FastestDet's grid."""
    if len(output_shapes) == 3:
        return "centernet"
    if len(output_shapes) == 1 and len(output_shapes[0]) == 4:
        return "fastestdet"
    if len(output_shapes) != 1 or len(output_shapes[0]) != 3:
        raise ValueError(f"cannot tell the detector's output format from shapes {list(output_shapes)}; name it explicitly")
    _, a, b = output_shapes[0]
    if isinstance(a, int) and isinstance(b, int) and a < b:
        return "yolov8"
    if isinstance(a, int) and a == len(yolox_grid(input_hw)[0]):
        return "yolox"
    return "yolov5"


def _cxcywh_to_xyxy(b: FloatArray) -> FloatArray:
    b = b.reshape(-1, 4)
    return np.stack([b[:, 0] - b[:, 2] / 2, b[:, 1] - b[:, 3] / 2, b[:, 0] + b[:, 2] / 2, b[:, 1] + b[:, 3] / 2], 1)
