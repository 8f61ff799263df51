"""Feet placement of a rotation-aware detector's boxes on rendered frames with known floor positions."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.detect.coco import rotated_to_xyxy
from bevflow.detect.rotated import outline_xyxy, radial_boxes
from bevflow.detections import Boxes
from bevflow.evaluation.placement import FITS, PlacementFrame, feet_errors, render_frame, render_frames

FloatArray = np.ndarray


class Replies:
    """Stands in for the detector: for each frame in turn, boxes made from the people's own."""

    def __init__(self, make: object) -> None:
        self.make = make

    def detect_boxes(self, image, camera_height_m, focal_px, centre):  # noqa: ANN001, ANN201
        frame = self.frames.pop(0)
        return self.make(frame, centre)  # type: ignore[operator]

    def run(self, frames: list[PlacementFrame]) -> dict[str, FloatArray]:
        self.frames = list(frames)
        return feet_errors(self, frames)


def _own_boxes(frame: PlacementFrame, centre: tuple[float, float]) -> tuple[Boxes, FloatArray]:
    return Boxes(frame.boxes), radial_boxes(frame.boxes, centre)


def _outlines(frame: PlacementFrame, centre: tuple[float, float]) -> tuple[Boxes, FloatArray]:
    rotated = radial_boxes(frame.boxes, centre)
    return Boxes(outline_xyxy(rotated)), rotated


def _nobody(frame: PlacementFrame, centre: tuple[float, float]) -> tuple[Boxes, FloatArray]:
    far = np.array([[0.0, 0.0, 3.0, 3.0]])  # a corner outside the image circle
    return Boxes(far), radial_boxes(far, centre)


@pytest.fixture(scope="module")
def frames() -> list[PlacementFrame]:
    return list(render_frames(3, zoom=1.0, seed=5, seated=0.0))


def test_frames_are_rendered_with_their_people_where_they_stand(frames: list[PlacementFrame]) -> None:
    assert sum(len(f.boxes) for f in frames) >= 6
    for f in frames:
        assert 3.0 <= f.height_m <= 5.0 and len(f.feet) == len(f.boxes)
        h, w = f.image.shape[:2]
        assert f.centre == pytest.approx(((w - 1) / 2, (h - 1) / 2))
        # each person's feet project inside (or at the foot of) their own box
        uv = f.camera.project(np.column_stack([f.feet, np.zeros(len(f.feet))]))
        inside = (uv[:, 0] >= f.boxes[:, 0] - 2) & (uv[:, 0] <= f.boxes[:, 2] + 2)
        assert inside.all()
    again = render_frame(np.random.default_rng([5, 0]), 1.0, seated=0.0)
    assert np.array_equal(again.image, frames[0].image) and np.array_equal(again.feet, frames[0].feet)


@pytest.mark.parametrize(
    ("make", "same_as_rendered", "matched"),
    [
        (_own_boxes, ("pipeline",), True),  # the people's own boxes: placed as the rendered boxes are
        (_outlines, (), True),  # turned radially and back through their outline: other boxes, same people
        (_nobody, (), False),  # a box on nobody is not matched, and nothing is scored
    ],
)
def test_every_fit_scores_the_same_matched_people(frames: list[PlacementFrame], make: object, same_as_rendered: tuple,
                                                  matched: bool) -> None:  # fmt: skip
    errors = Replies(make).run(frames)
    assert set(errors) == set(FITS)
    counts = {len(e) for e in errors.values()}
    assert len(counts) == 1 and (counts.pop() > 0) == matched
    for name in same_as_rendered:
        assert np.allclose(errors[name], errors["rendered"])
    if matched:
        assert errors["rendered"].max() < 1.0  # upright people from their own boxes: placed near where they stand


def test_the_enclosing_fit_uses_the_rotated_boxes_enclosing_rectangle(frames: list[PlacementFrame]) -> None:
    errors = Replies(_outlines).run(frames)
    own = Replies(lambda f, c: (Boxes(rotated_to_xyxy(radial_boxes(f.boxes, c))), radial_boxes(f.boxes, c))).run(frames)
    assert np.allclose(errors["enclosing"], own["pipeline"])
