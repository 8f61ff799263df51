"""Head heights measured from boxes (``bevflow.stature``): cuboid boxes of people of known height
through a side camera and a ceiling fisheye (built as in ``test_cylinder``)."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera
from bevflow.cylinder import fit_cylinders
from bevflow.detections import Boxes, Cylinders
from bevflow.stature import measure_stature
from tests.bevflow.test_cylinder import cuboid_box, side_pinhole

SIDE = side_pinhole(70.0)
CEILING = FisheyeCamera.looking_down(position=(0.0, 0.0, 3.3), image_size=(1024, 1024), fov_deg=185)


@pytest.mark.parametrize(("x", "y", "height"), [(0.0, 5.0, 1.55), (0.5, 7.0, 1.70), (-0.8, 9.0, 1.85), (0.6, 5.0, 1.90),
                                                (1.0, 12.0, 1.62)])
def test_a_side_camera_measures_the_head_height(x: float, y: float, height: float) -> None:
    boxes = Boxes([cuboid_box(SIDE, x, y, height, 0.25)])
    cylinders = fit_cylinders(SIDE, boxes)
    measured = measure_stature(SIDE, boxes, cylinders)
    # The fit's height differs from the person's by up to 0.1 m here; the measurement is off
    # only by what the fitted feet's range error carries into it.
    assert measured[0] == pytest.approx(height, abs=0.06)


def test_people_of_different_heights_measure_apart() -> None:
    heights = (1.60, 1.75, 1.90)
    boxes = Boxes([cuboid_box(SIDE, 0.3 * k, 5.0, h, 0.25) for k, h in enumerate(heights)])
    measured = measure_stature(SIDE, boxes, fit_cylinders(SIDE, boxes))
    assert np.all(np.diff(measured) > 0.1)


@pytest.mark.parametrize(("radius", "bearing", "why"), [(0.3, 0.7, "below the camera the head hides in the box"),
                                                        (1.5, 0.7, "the head moves diagonally across the box"),
                                                        (3.0, 0.0, "the head is seen from 28° above")])
def test_a_ceiling_fisheye_measures_nothing_where_its_boxes_cannot_tell(radius: float, bearing: float, why: str) -> None:
    x, y = radius * np.cos(bearing), radius * np.sin(bearing)
    boxes = Boxes([cuboid_box(CEILING, x, y, 1.7, 0.25)])
    assert np.isnan(measure_stature(CEILING, boxes, fit_cylinders(CEILING, boxes))).all(), why


@pytest.mark.parametrize(("score", "occluded"), [(0.0, False), (0.8, True)])
def test_a_weak_or_rebuilt_fit_measures_nothing(score: float, occluded: bool) -> None:
    boxes = Boxes([cuboid_box(SIDE, 0.0, 6.0, 1.8, 0.25)])
    fitted = fit_cylinders(SIDE, boxes)
    cylinders = Cylinders(xy=fitted.xy, score=[score], occluded=[occluded])
    assert np.isnan(measure_stature(SIDE, boxes, cylinders)).all()


def test_a_height_out_of_range_is_not_reported() -> None:
    boxes = Boxes([cuboid_box(SIDE, 0.0, 6.0, 2.6, 0.25)])  # taller than anyone in HEIGHTS_M
    cylinders = Cylinders(xy=[(0.0, 6.0)], score=[0.9])
    assert np.isnan(measure_stature(SIDE, boxes, cylinders)).all()


def test_boxes_and_cylinders_must_go_row_for_row() -> None:
    with pytest.raises(ValueError, match="row for row"):
        measure_stature(SIDE, Boxes([[0, 0, 10, 10]]), Cylinders.empty())
