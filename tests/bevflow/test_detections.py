"""The columnar stage types: construction, defaults, slicing, merging, and shape errors."""

from __future__ import annotations

import doctest
from dataclasses import replace

import numpy as np
import pytest

import bevflow.detections
from bevflow.detections import Boxes, Cylinders, nms


def _cylinders(n: int, camera: int = 0, offset: float = 0.0) -> Cylinders:
    i = np.arange(n, dtype=float) + offset
    return Cylinders(
        xy=np.stack([i, -i], axis=1),
        height=1.5 + 0.01 * i,
        radius=0.2 + 0.01 * i,
        camera=np.full(n, camera),
        score=np.linspace(0.1, 0.9, n) if n else [],
        occluded=(np.arange(n) % 2 == 1),
    )


# --- Boxes ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("xyxy", "confidence", "expected_xyxy", "expected_confidence"),
    [
        pytest.param([[10, 20, 50, 90]], None, [[10, 20, 50, 90]], [1.0], id="confidence-defaults-to-1"),
        pytest.param([10, 20, 50, 90], [0.3], [[10, 20, 50, 90]], [0.3], id="one-flat-box"),
        pytest.param(
            np.array([[0, 0, 1, 1], [2, 2, 4, 5]], np.int32),
            np.array([0.5, 0.25], np.float32),
            [[0, 0, 1, 1], [2, 2, 4, 5]],
            [0.5, 0.25],
            id="casts-to-float64",
        ),
        pytest.param(np.zeros((0, 4)), None, np.zeros((0, 4)), [], id="empty"),
    ],
)
def test_boxes_construction(xyxy, confidence, expected_xyxy, expected_confidence) -> None:
    boxes = Boxes(xyxy=xyxy, confidence=confidence)
    assert boxes.xyxy.dtype == np.float64 and boxes.confidence.dtype == np.float64
    assert boxes.xyxy.shape == (len(expected_confidence), 4)
    np.testing.assert_array_equal(boxes.xyxy, expected_xyxy)
    np.testing.assert_array_equal(boxes.confidence, expected_confidence)
    assert len(boxes) == len(expected_confidence)


def test_boxes_empty() -> None:
    empty = Boxes.empty()
    assert len(empty) == 0 and empty.xyxy.shape == (0, 4) and empty.confidence.shape == (0,)
    assert empty.center.shape == (0, 2) and empty.corners().shape == (0, 4, 2)


def test_boxes_geometry() -> None:
    boxes = Boxes(xyxy=[[10, 20, 50, 90], [0, 0, 2, 4]])
    np.testing.assert_array_equal(boxes.width, [40, 2])
    np.testing.assert_array_equal(boxes.height, [70, 4])
    np.testing.assert_array_equal(boxes.center, [[30, 55], [1, 2]])
    np.testing.assert_array_equal(boxes.corners()[0], [[10, 20], [50, 20], [50, 90], [10, 90]])


BOXES = Boxes(xyxy=np.arange(20, dtype=float).reshape(5, 4), confidence=[0.1, 0.2, 0.3, 0.4, 0.5])


@pytest.mark.parametrize(
    ("index", "rows"),
    [
        pytest.param(2, [2], id="int-keeps-2d"),
        pytest.param(-1, [4], id="negative-int"),
        pytest.param(slice(1, 3), [1, 2], id="slice"),
        pytest.param(slice(None, None, -2), [4, 2, 0], id="reversed-step"),
        pytest.param(np.array([True, False, False, True, False]), [0, 3], id="mask"),
        pytest.param(np.array([3, 0, 3]), [3, 0, 3], id="fancy"),
        pytest.param(np.zeros(5, bool), [], id="mask-selects-nothing"),
    ],
)
def test_boxes_indexing(index, rows: list[int]) -> None:
    picked = BOXES[index]
    assert isinstance(picked, Boxes) and len(picked) == len(rows)
    np.testing.assert_array_equal(picked.xyxy, BOXES.xyxy[rows].reshape(-1, 4))
    np.testing.assert_array_equal(picked.confidence, BOXES.confidence[rows])


@pytest.mark.parametrize(
    ("xyxy", "confidence"),
    [
        pytest.param([[0, 0, 1, 1], [1, 1, 2, 2]], [0.5], id="too-few-confidences"),
        pytest.param([[0, 0, 1, 1]], [0.5, 0.6], id="too-many-confidences"),
    ],
)
def test_boxes_column_length_errors(xyxy, confidence) -> None:
    with pytest.raises(ValueError, match=rf"column has {len(confidence)} rows, expected {len(xyxy)}"):
        Boxes(xyxy=xyxy, confidence=confidence)


def test_boxes_are_frozen() -> None:
    with pytest.raises(AttributeError):
        BOXES.xyxy = np.zeros((0, 4))  # type: ignore[misc]


def test_boxes_reject_arrays_that_are_not_n_by_4() -> None:
    with pytest.raises(ValueError):
        Boxes(xyxy=np.arange(12.0).reshape(4, 3))


def test_boxes_merge() -> None:
    merged = Boxes.merge([BOXES[:2], Boxes.empty(), BOXES[3:]])
    np.testing.assert_array_equal(merged.confidence, [0.1, 0.2, 0.4, 0.5])


# --- Cylinders ------------------------------------------------------------------------------------
def test_cylinders_defaults() -> None:
    c = Cylinders(xy=[[1.0, 2.0], [3.0, 4.0]])
    np.testing.assert_array_equal(c.height, [1.7, 1.7])
    np.testing.assert_array_equal(c.radius, [0.3, 0.3])
    np.testing.assert_array_equal(c.camera, [-1, -1])
    np.testing.assert_array_equal(c.score, [1.0, 1.0])
    np.testing.assert_array_equal(c.occluded, [False, False])
    assert (c.xy.dtype, c.height.dtype, c.camera.dtype, c.occluded.dtype) == (
        np.float64,
        np.float64,
        np.int64,
        np.bool_,
    )


def test_cylinders_keep_given_columns() -> None:
    c = _cylinders(3, camera=2)
    np.testing.assert_array_equal(c.xy, [[0, 0], [1, -1], [2, -2]])
    np.testing.assert_allclose(c.height, [1.5, 1.51, 1.52])
    np.testing.assert_array_equal(c.camera, [2, 2, 2])
    np.testing.assert_array_equal(c.occluded, [False, True, False])


def test_cylinders_empty() -> None:
    empty = Cylinders.empty()
    assert len(empty) == 0 and empty.xy.shape == (0, 2)
    for column in (empty.height, empty.radius, empty.camera, empty.score, empty.occluded):
        assert column.shape == (0,)


@pytest.mark.parametrize(
    ("index", "rows"),
    [
        pytest.param(1, [1], id="int"),
        pytest.param(slice(2, None), [2, 3], id="slice"),
        pytest.param(np.array([False, True, False, True]), [1, 3], id="mask"),
        pytest.param(np.array([2, 2]), [2, 2], id="fancy"),
    ],
)
def test_cylinders_indexing_keeps_rows_together(index, rows: list[int]) -> None:
    c = _cylinders(4, camera=1)
    picked = c[index]
    assert len(picked) == len(rows)
    np.testing.assert_array_equal(picked.xy, c.xy[rows])
    for name in ("height", "radius", "camera", "score", "occluded"):
        np.testing.assert_array_equal(getattr(picked, name), getattr(c, name)[rows], err_msg=name)


def test_cylinders_merge_concatenates_in_order_and_skips_empty() -> None:
    a, b = _cylinders(2, camera=0), _cylinders(3, camera=1, offset=10.0)
    merged = Cylinders.merge([a, Cylinders.empty(), b])
    assert len(merged) == 5
    np.testing.assert_array_equal(merged.camera, [0, 0, 1, 1, 1])
    np.testing.assert_array_equal(merged.xy[:, 0], [0, 1, 10, 11, 12])
    np.testing.assert_array_equal(merged.occluded, [False, True, False, True, False])
    np.testing.assert_array_equal(merged.score, np.concatenate([a.score, b.score]))


@pytest.mark.parametrize("parts", [[], [Cylinders.empty()], [Cylinders.empty(), Cylinders.empty()]])
def test_cylinders_merge_of_nothing_is_empty(parts: list[Cylinders]) -> None:
    merged = Cylinders.merge(parts)
    assert len(merged) == 0 and merged.xy.shape == (0, 2)


def test_cylinders_with_camera_relabels_every_row() -> None:
    c = _cylinders(3, camera=0).with_camera(4)
    np.testing.assert_array_equal(c.camera, [4, 4, 4])
    assert c.camera.dtype == np.int64


@pytest.mark.parametrize("column", ["height", "radius", "camera", "score", "occluded"])
@pytest.mark.parametrize("length", [1, 3])
def test_cylinders_column_length_errors(column: str, length: int) -> None:
    with pytest.raises(ValueError, match=rf"column has {length} rows, expected 2"):
        Cylinders(xy=np.zeros((2, 2)), **{column: np.zeros(length)})


def _covariances(n: int, scale: float = 1.0) -> np.ndarray:
    """(n, 2, 2) distinct covariances: row k is diag(k + 1, 2k + 1) · scale with 0.1 · scale off the diagonal."""
    k = np.arange(n, dtype=float)
    return scale * np.stack([np.stack([k + 1, np.full(n, 0.1)], 1), np.stack([np.full(n, 0.1), 2 * k + 1], 1)], 1)


def test_cylinders_have_no_covariance_unless_given() -> None:
    assert _cylinders(3).covariance is None
    assert Cylinders.merge([_cylinders(2), _cylinders(1)]).covariance is None
    assert _cylinders(3)[1:].covariance is None


@pytest.mark.parametrize(
    ("index", "rows"),
    [pytest.param(1, [1], id="int"), pytest.param(np.array([True, False, True]), [0, 2], id="mask")],
)
def test_cylinders_indexing_keeps_covariance_rows(index, rows: list[int]) -> None:
    cov = _covariances(3)
    picked = replace(_cylinders(3), covariance=cov)[index]
    np.testing.assert_array_equal(picked.covariance, cov[rows])


def test_cylinders_merge_fills_unknown_covariances_with_nan() -> None:
    a = replace(_cylinders(2), covariance=_covariances(2))
    merged = Cylinders.merge([a, _cylinders(1, camera=1), Cylinders.empty()])
    assert merged.covariance.shape == (3, 2, 2)
    np.testing.assert_array_equal(merged.covariance[:2], _covariances(2))
    assert np.isnan(merged.covariance[2]).all()


def test_cylinders_reject_covariance_of_the_wrong_shape() -> None:
    with pytest.raises(ValueError, match=r"covariance must have shape \(2, 2, 2\)"):
        Cylinders(xy=np.zeros((2, 2)), covariance=np.zeros((3, 2, 2)))


def test_cylinders_reject_points_that_are_not_n_by_2() -> None:
    with pytest.raises(ValueError):
        Cylinders(xy=np.zeros((2, 3)))


def test_docstring_examples() -> None:
    assert doctest.testmod(bevflow.detections).failed == 0


@pytest.mark.parametrize(
    "radius, expected",
    [
        (None, [True, True, True, True]),
        (2.0, [True, True, False, True]),  # the unknown feet stay, for fusion to judge
        (0.5, [True, False, False, True]),
    ],
)
def test_near_keeps_feet_within_the_radius(radius, expected) -> None:
    xy = np.array([[1.0, 1.0], [2.0, 2.5], [4.0, 1.0], [np.nan, np.nan]])
    cylinders = Cylinders(xy=xy, height=np.full(4, 1.7), radius=np.full(4, 0.25))
    assert cylinders.near((1.0, 1.0, 5.5), radius).tolist() == expected


@pytest.mark.parametrize(
    ("boxes", "scores", "iou", "kept"),
    [
        ([[0, 0, 10, 10], [1, 0, 11, 10], [50, 50, 60, 60]], [0.9, 0.8, 0.7], 0.5, [0, 2]),
        ([[0, 0, 10, 10], [1, 0, 11, 10]], [0.5, 0.8], 0.5, [1]),
        ([[0, 0, 10, 10], [5, 0, 15, 10]], [0.9, 0.8], 0.5, [0, 1]),  # IoU 1/3
        ([[0, 0, 10, 10], [5, 0, 15, 10]], [0.9, 0.8], 0.3, [0]),
        (np.zeros((0, 4)), [], 0.5, []),
    ],
)
def test_nms(boxes, scores, iou, kept) -> None:  # noqa: ANN001
    assert nms(np.array(boxes, float), np.array(scores, float), iou).tolist() == kept
