from __future__ import annotations

import numpy as np
import pytest

from bevflow.training.augment import boxes_from_owner, clahe, flip, rotate, rotate_rotated_boxes
from bevflow.training.dataset import IGNORE


def _scene() -> tuple[np.ndarray, np.ndarray]:
    owner = np.full((41, 41), -1, np.int16)
    owner[5:9, 20:30] = 0  # a 10 x 4 person
    owner[30:36, 3:7] = 1
    image = np.zeros((41, 41, 3), np.uint8)
    image[owner >= 0] = 200
    return image, owner


def test_boxes_from_owner_are_pixel_bounds() -> None:
    _, owner = _scene()
    boxes, ignore = boxes_from_owner(owner)
    np.testing.assert_allclose(boxes, [[19.5, 4.5, 29.5, 8.5], [2.5, 29.5, 6.5, 35.5]])
    assert ignore.tolist() == [False, False]


@pytest.mark.parametrize(
    ("reference", "ignored"),
    [(None, [False, False]), (np.array([40, 24]), [False, False]), (np.array([200, 24]), [True, False])],
)
def test_people_cut_by_the_crop_are_ignored(reference, ignored) -> None:  # noqa: ANN001
    _, owner = _scene()
    assert boxes_from_owner(owner, reference)[1].tolist() == ignored


def test_slivers_are_ignored() -> None:
    owner = np.full((20, 20), -1, np.int16)
    owner[3:5, 3:8] = 0  # 10 pixels
    assert boxes_from_owner(owner)[1].tolist() == [True]
    assert boxes_from_owner(owner, min_pixels=6)[1].tolist() == [False]


def test_hidden_people_become_ignore_boxes() -> None:
    _, owner = _scene()
    owner[20:23, 20:22] = IGNORE
    boxes, ignore = boxes_from_owner(owner)
    assert ignore.tolist() == [False, False, True]
    np.testing.assert_allclose(boxes[2], [19.5, 19.5, 21.5, 22.5])


def test_rotation_by_90_degrees_turns_the_boxes_exactly() -> None:
    image, owner = _scene()
    img90, own90 = rotate(image, owner, 90.0)
    boxes, _ = boxes_from_owner(own90)
    # Counter-clockwise about the centre (20, 20): (x, y) -> (y, 40 - x).
    np.testing.assert_allclose(boxes[0], [4.5, 10.5, 8.5, 20.5])
    assert img90[own90 >= 0].min() == 200


def test_flip_mirrors_boxes() -> None:
    image, owner = _scene()
    _, own = flip(image, owner)
    boxes, _ = boxes_from_owner(own)
    np.testing.assert_allclose(boxes[0], [40 - 29.5, 4.5, 40 - 19.5, 8.5])


def test_clahe_keeps_shape_and_raises_contrast() -> None:
    rng = np.random.default_rng(0)
    dull = (100 + rng.integers(0, 10, (64, 64, 3))).astype(np.uint8)
    out = clahe(dull)
    assert out.shape == dull.shape and out.dtype == np.uint8
    assert out.std() > dull.std()


@pytest.mark.parametrize(("angle", "expected"), [(90.0, [10.0, 10.0, 4.0, 8.0, -90.0]), (0.0, [30.0, 10.0, 4.0, 8.0, 0.0])])
def test_rotated_boxes_turn_with_the_image(angle: float, expected: list[float]) -> None:
    out = rotate_rotated_boxes(np.array([[30.0, 10.0, 4.0, 8.0, 0.0]]), angle, (20.0, 20.0))
    np.testing.assert_allclose(out, [expected], atol=1e-9)
