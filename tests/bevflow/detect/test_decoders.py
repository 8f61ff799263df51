from __future__ import annotations

import numpy as np
import pytest

from bevflow.detect.decoders import (
    decode_centernet,
    decode_fastestdet,
    decode_yolov5,
    decode_yolov8,
    decode_yolox,
    guess_format,
    yolox_grid,
)


def test_decode_centernet_places_the_box_at_the_peak() -> None:
    heat = np.zeros((1, 1, 8, 10), np.float32)
    heat[0, 0, 3, 5] = 0.9
    heat[0, 0, 6, 1] = 0.2  # under the threshold
    size = np.zeros((1, 2, 8, 10), np.float32)
    size[0, :, 3, 5] = (12.0, 20.0)
    offset = np.zeros((1, 2, 8, 10), np.float32)
    offset[0, :, 3, 5] = (0.5, 0.25)
    xyxy, scores = decode_centernet(heat, size, offset, 0.3)
    cx, cy = 4 * 5.5 - 0.5, 4 * 3.25 - 0.5
    np.testing.assert_allclose(xyxy, [[cx - 6, cy - 10, cx + 6, cy + 10]])
    np.testing.assert_allclose(scores, [0.9], rtol=1e-6)


def test_decode_yolov5_keeps_people_only() -> None:
    rows = np.array(
        [
            [50, 40, 10, 20, 0.9, 0.8, 0.1],  # person
            [10, 10, 4, 4, 0.9, 0.1, 0.9],  # another class wins
            [70, 70, 8, 8, 0.2, 0.9, 0.0],  # low objectness: 0.18
        ]
    )
    xyxy, scores = decode_yolov5(rows[None], 0.25)
    np.testing.assert_allclose(xyxy, [[45, 30, 55, 50]])
    np.testing.assert_allclose(scores, [0.72])


def test_decode_yolov8_reads_columns() -> None:
    cols = np.array([[50.0, 10.0], [40.0, 10.0], [10.0, 4.0], [20.0, 4.0], [0.7, 0.2], [0.1, 0.9]])
    xyxy, scores = decode_yolov8(cols[None], 0.25)
    np.testing.assert_allclose(xyxy, [[45, 30, 55, 50]])
    np.testing.assert_allclose(scores, [0.7])


def test_decode_yolox_undoes_the_grid() -> None:
    hw = (64, 64)
    grid, stride = yolox_grid(hw)
    assert len(grid) == 8 * 8 + 4 * 4 + 2 * 2
    rows = np.zeros((len(grid), 6))
    k = 8 * 8 + 5  # stride 16, cell (1, 1)
    rows[k] = [0.5, 0.25, np.log(2.0), 0.0, 0.9, 1.0]
    xyxy, scores = decode_yolox(rows[None], hw, 0.5)
    cx, cy = (1 + 0.5) * 16, (1 + 0.25) * 16
    np.testing.assert_allclose(xyxy, [[cx - 16, cy - 8, cx + 16, cy + 8]])
    np.testing.assert_allclose(scores, [0.9])


def test_decode_yolox_checks_the_row_count() -> None:
    with pytest.raises(ValueError, match="rows"):
        decode_yolox(np.zeros((1, 10, 6)), (64, 64), 0.5)


@pytest.mark.parametrize(
    ("shapes", "expected"),
    [
        ([[1, 1, "h", "w"], [1, 2, "h", "w"], [1, 2, "h", "w"]], "centernet"),
        ([[1, 84, 8400]], "yolov8"),
        ([[1, 25200, 85]], "yolov5"),
        ([[1, 8400, 85]], "yolox"),
        ([[1, 85, 22, 22]], "fastestdet"),
    ],
)
def test_guess_format(shapes, expected) -> None:  # noqa: ANN001
    assert guess_format(shapes, (640, 640)) == expected


def test_guess_format_refuses_unknown_layouts() -> None:
    with pytest.raises(ValueError, match="explicitly"):
        guess_format([[1, 4], [1, 4]], (640, 640))


def test_decode_fastestdet_reads_one_box_per_cell() -> None:
    grid = np.zeros((1 + 4 + 2, 4, 4))  # objectness, box, two classes, on a 4 × 4 grid
    grid[0, 1, 2], grid[5, 1, 2], grid[6, 1, 2] = 0.8, 0.9, 0.1  # a person in row 1, column 2
    grid[1:5, 1, 2] = [0.0, np.arctanh(0.5), 0.0, np.log(3.0)]  # centre (2, 1.5) cells; w 1/2, h 3/4 of the input
    grid[0, 3, 3], grid[6, 3, 3] = 0.9, 0.9  # another class
    xyxy, scores = decode_fastestdet(grid, (64, 64), 0.3)
    assert scores == pytest.approx([0.8**0.6 * 0.9**0.4])
    assert xyxy[0] == pytest.approx([32 - 16, 24 - 24, 32 + 16, 24 + 24])
