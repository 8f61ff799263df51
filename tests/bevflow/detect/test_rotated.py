"""Rotated boxes: exact IoU between rotated rectangles, radial angles, axis-aligned → radial."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bevflow.detect.coco import rotated_to_xyxy
from bevflow.detect.rotated import (
    convex_intersection,
    outline_xyxy,
    polygon_area,
    radial_angle,
    radial_boxes,
    rotated_corners,
    rotated_iou_matrix,
)

OCTAGON = 4 * (2 * math.sqrt(2) - 2)  # a 2 × 2 square ∩ itself turned 45°: a regular octagon


@pytest.mark.parametrize(
    ("a", "b", "expected"),
    [
        ([0, 0, 2, 2, 0], [0, 0, 2, 2, 0], 1.0),  # the same box
        ([0, 0, 2, 2, 0], [1, 0, 2, 2, 0], 2 / 6),  # half a width apart: 2 / (4 + 4 - 2)
        ([0, 0, 2, 2, 0], [5, 5, 2, 2, 0], 0.0),  # apart
        ([0, 0, 2, 2, 0], [3, 0, 2, 2, 45], 0.0),  # the turned square's enclosing box touches, the square does not
        ([0, 0, 2, 2, 0], [0, 0, 2, 2, 45], OCTAGON / (8 - OCTAGON)),
        ([0, 0, 2, 4, 0], [0, 0, 4, 2, 90], 1.0),  # the same rectangle described turned
        ([0, 0, 2, 4, 0], [0, 0, 2, 4, 90], 4 / 12),  # a cross: 2 × 2 shared of 8 + 8
        ([0, 0, 2, 4, 30], [0, 0, 2, 4, 210], 1.0),  # half a turn is the same box
        ([0, 0, 2, 2, 0], [0, 0, 4, 4, 17], 4 / 16),  # inside, whatever the outer box's angle
        ([10, 20, 3, 5, -60], [10, 20, 3, 5, -60], 1.0),
    ],
)
def test_rotated_iou(a: list[float], b: list[float], expected: float) -> None:
    assert rotated_iou_matrix(np.array([a]), np.array([b]))[0, 0] == pytest.approx(expected, abs=1e-9)
    assert rotated_iou_matrix(np.array([b]), np.array([a]))[0, 0] == pytest.approx(expected, abs=1e-9)


def test_rotated_iou_agrees_with_opencv() -> None:
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.uniform(0, 10, (60, 2)), rng.uniform(1, 6, (60, 2)), rng.uniform(-180, 180, 60)])
    b = a + np.column_stack([rng.uniform(-3, 3, (60, 2)), rng.uniform(-0.9, 3, (60, 2)), rng.uniform(-90, 90, 60)])
    mine = rotated_iou_matrix(a, b).diagonal()
    for k, (p, q) in enumerate(zip(a, b, strict=True)):
        _, pts = cv2.rotatedRectangleIntersection(((p[0], p[1]), (p[2], p[3]), p[4]), ((q[0], q[1]), (q[2], q[3]), q[4]))
        inter = cv2.contourArea(cv2.convexHull(pts.astype(np.float32))) if pts is not None else 0.0
        assert mine[k] == pytest.approx(inter / (p[2] * p[3] + q[2] * q[3] - inter), abs=1e-4)


def test_corners_follow_opencv_box_points() -> None:
    box = np.array([100.0, 50.0, 20.0, 60.0, 33.0])
    ours = rotated_corners(box)[0]
    theirs = cv2.boxPoints(((box[0], box[1]), (box[2], box[3]), box[4]))
    assert sorted(map(tuple, np.round(ours, 3))) == sorted(map(tuple, np.round(theirs.astype(np.float64), 3)))


def test_empty_inputs() -> None:
    assert rotated_iou_matrix(np.zeros((0, 5)), np.array([[0, 0, 1, 1, 0]])).shape == (0, 1)
    assert polygon_area(convex_intersection(np.zeros((0, 2)), rotated_corners(np.array([0, 0, 1, 1, 0]))[0])) == 0.0


@pytest.mark.parametrize(
    ("x", "y", "degrees"),
    [(0, 10, 0.0), (-10, 0, 90.0), (10, 0, -90.0), (0, -10, 180.0), (-10, 10, 45.0), (10, 10, -45.0)],
)
def test_radial_angle_turns_the_box_up_axis_to_the_centre(x: float, y: float, degrees: float) -> None:
    assert abs(radial_angle(np.array([x]), np.array([y]), (0.0, 0.0))[0]) == pytest.approx(abs(degrees))
    # The box's up axis (0, -1) turned by the angle points from the box to the centre.
    a = math.radians(radial_angle(np.array([x]), np.array([y]), (0.0, 0.0))[0])
    up = np.array([math.sin(a), -math.cos(a)])
    assert np.dot(up, -np.array([x, y]) / math.hypot(x, y)) == pytest.approx(1.0)


@pytest.mark.parametrize("degrees", [0.0, 10.0, 25.0, 60.0, 80.0, 100.0, 160.0, -120.0])
def test_radial_boxes_recover_a_radial_person_from_its_enclosing_box(degrees: float) -> None:
    a = math.radians(degrees)
    centre = (500.0, 400.0)
    cx, cy = centre[0] - 200 * math.sin(a), centre[1] + 200 * math.cos(a)  # below the centre, turned
    person = np.array([[cx, cy, 30.0, 80.0, degrees]])
    back = radial_boxes(rotated_to_xyxy(person), centre)
    assert back[0, :4] == pytest.approx(person[0, :4], abs=1e-6)
    assert rotated_iou_matrix(back, person)[0, 0] == pytest.approx(1.0)


def test_radial_boxes_near_45_degrees_blend_into_a_square_with_the_same_enclosing_box() -> None:
    box = np.array([[100.0, 100.0, 150.0, 150.0]])  # 45° below-right of the origin
    back = radial_boxes(box, (0.0, 0.0))
    assert back[0, 2] == pytest.approx(back[0, 3])
    assert rotated_to_xyxy(back)[0] == pytest.approx(box[0])


@pytest.mark.parametrize(
    ("box", "expected"),
    [
        ([50, 40, 10, 30, 0], [45, 25, 55, 55]),  # upright: the box itself
        ([50, 40, 10, 30, 90], [35, 35, 65, 45]),  # a quarter turn: width and height swap
        ([50, 40, 10, 30, 180], [45, 25, 55, 55]),  # a half turn is the same box
        ([0, 0, 20, 20, 45], [-10, -10, 10, 10]),  # a square's circle is the same at every angle
        ([0, 0, 10, 30, 45], [-(500**0.5) / 2, -(500**0.5) / 2, (500**0.5) / 2, (500**0.5) / 2]),  # √((10² + 30²) / 2)
        ([0, 0, 10, 30, 30], [-(300**0.5) / 2, -(700**0.5) / 2, (300**0.5) / 2, (700**0.5) / 2]),  # (10 cos, 30 sin) and (10 sin, 30 cos)
    ],
)
def test_outline_is_the_upright_box_of_the_ellipse_inside(box: list[float], expected: list[float]) -> None:
    got = outline_xyxy(np.array([box], float))[0]
    assert got == pytest.approx(expected, abs=1e-3)
    enclosing = rotated_to_xyxy(np.array([box], float))[0]
    assert (got[:2] >= enclosing[:2] - 1e-9).all() and (got[2:] <= enclosing[2:] + 1e-9).all()  # inside the rectangle's
