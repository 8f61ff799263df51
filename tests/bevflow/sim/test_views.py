from __future__ import annotations

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera
from bevflow.sim.bodies import BodyShape, Posture
from bevflow.sim.scene import Obstacles, Pillar, Scene, SceneConfig, SceneFrame, Shelf
from bevflow.sim.views import CameraRig, CameraView, GroundTruthTracks, observe_scene

CAM = FisheyeCamera.looking_down((0.0, 0.0, 3.3), (1280, 1280), 185.0, 0.0, (0.012, -0.003, 0.0005, 0.0))
CENTRE = np.array([639.5, 639.5])


def people(xy, heading=None, posture=Posture.STANDING, height: float = 1.72) -> SceneFrame:
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n = len(xy)
    return SceneFrame(
        index=0,
        time_s=0.0,
        person_ids=np.arange(1, n + 1),
        identity=np.arange(n),
        group=np.full(n, -1),
        feet_xy=xy,
        heading=np.zeros(n) if heading is None else np.asarray(heading, dtype=np.float64),
        gait_phase=np.zeros(n),
        speed=np.zeros(n),
        posture=np.full(n, int(posture)),
        body=BodyShape.standard(n, height),
    )


def one_view(frame: SceneFrame, obstacles: Obstacles | None = None, radius: float | None = 3.5) -> CameraView:
    (view,) = CameraRig([CAM], [radius], obstacles).observe(frame)
    return view


def row(view: CameraView, person_id: int) -> int | None:
    hits = np.flatnonzero(view.person_ids == person_id)
    return int(hits[0]) if len(hits) else None


@pytest.mark.parametrize("heading", [0.0, 1.0, 2.5])
def test_a_person_straight_below_the_camera_is_boxed_around_the_image_centre(heading: float) -> None:
    view = one_view(people([[0.0, 0.0]], heading=[heading]))
    assert view.person_ids.tolist() == [1]
    box = view.boxes.xyxy[0]
    assert np.abs(view.boxes.center[0] - CENTRE).max() < 25
    assert box[0] < CENTRE[0] < box[2] and box[1] < CENTRE[1] < box[3]
    # Seen from 1.6 m above the head, shoulders 0.45 m wide span roughly f·0.45/1.6 ≈ 110 px.
    assert 70 < max(view.boxes.width[0], view.boxes.height[0]) < 160
    assert view.visible_fraction[0] == 1.0 and not view.lower_occluded[0]


def test_an_unoccluded_box_spans_the_projections_of_head_top_and_feet() -> None:
    view = one_view(people([[2.0, 1.0]]))
    x0, y0, x1, y1 = view.boxes.xyxy[0]
    head, feet = CAM.project(np.array([[2.0, 1.0, 1.70], [2.0, 1.0, 0.02]]))
    for p in (head, feet):
        assert x0 - 2 <= p[0] <= x1 + 2 and y0 - 2 <= p[1] <= y1 + 2
    np.testing.assert_allclose(view.feet_xy, [[2.0, 1.0]])


@pytest.mark.parametrize(
    ("obstacle", "expect"),
    [
        (Obstacles((Pillar(1.5, 0.0, 0.3, 3.3),)), "dropped"),  # a column right between camera and person
        (Obstacles(shelves=(Shelf(1.6, -0.6, 1.9, 0.6, 1.1),)), "lower_occluded"),  # a counter hides the legs
        (Obstacles((Pillar(1.5, 2.0, 0.3, 3.3),)), "unaffected"),  # off to the side
    ],
)
def test_static_obstacles_hide_people_behind_them(obstacle: Obstacles, expect: str) -> None:
    frame = people([[2.3, 0.0]])
    clear, hidden = one_view(frame), one_view(frame, obstacle)
    assert clear.person_ids.tolist() == [1] and not clear.lower_occluded[0]
    if expect == "dropped":
        assert len(hidden) == 0
    elif expect == "lower_occluded":
        assert hidden.lower_occluded[0] and hidden.visible_fraction[0] < 0.9
        assert hidden.boxes.width[0] < clear.boxes.width[0] - 10  # the feet side, toward the centre, is cut
        assert hidden.boxes.xyxy[0, 2] == pytest.approx(clear.boxes.xyxy[0, 2], abs=1.0)  # the head side is not
    else:
        np.testing.assert_allclose(hidden.boxes.xyxy, clear.boxes.xyxy)
        assert hidden.visible_fraction[0] == 1.0


def test_a_person_nearer_the_camera_hides_the_legs_of_one_behind() -> None:
    view = one_view(people([[1.2, 0.0], [1.8, 0.0]]))
    near, far = row(view, 1), row(view, 2)
    assert near is not None and far is not None
    assert view.visible_fraction[near] == 1.0 and not view.lower_occluded[near]
    assert view.visible_fraction[far] < 0.8 and view.lower_occluded[far]
    alone = one_view(people([[1.8, 0.0]]))
    assert view.boxes.xyxy[far, 0] > alone.boxes.xyxy[0, 0] + 5  # feet side cut off


def test_people_side_by_side_do_not_hide_each_other() -> None:
    view = one_view(people([[2.0, -0.6], [2.0, 0.6]]))
    np.testing.assert_array_equal(view.visible_fraction, [1.0, 1.0])


@pytest.mark.parametrize(
    ("x", "radius", "seen"), [(3.0, 3.5, True), (4.0, 3.5, False), (4.0, None, True), (9.0, 8.0, False)]
)
def test_only_people_inside_the_monitored_radius_are_in_the_view(x: float, radius: float | None, seen: bool) -> None:
    assert len(one_view(people([[x, 0.0]]), radius=radius)) == int(seen)


def test_boxes_stay_inside_the_image_and_rows_line_up() -> None:
    config = SceneConfig(floor=(-4.0, -4.0, 4.0, 4.0), identities=12, frames=20, seed=3)
    rig = CameraRig([CAM], [None])
    for frame, (view,) in observe_scene(rig, Scene(config)):
        n = len(view)
        assert len(view.boxes) == len(view.visible_fraction) == len(view.lower_occluded) == len(view.feet_xy) == n
        assert np.all(view.boxes.xyxy >= 0) and np.all(view.boxes.xyxy[:, [2, 3]] <= 1279)
        assert np.all(view.boxes.width > 0) and np.all(view.boxes.height > 0)
        assert np.all(view.visible_fraction >= rig.min_visible_fraction)
        for pid, xy in zip(view.person_ids, view.feet_xy, strict=True):
            np.testing.assert_array_equal(frame.feet_xy[frame.person_ids == pid][0], xy)


def test_views_are_deterministic_and_cameras_are_independent() -> None:
    frame = people([[0.5, 0.5], [-1.5, 1.0], [2.0, -2.0]])
    other = FisheyeCamera.looking_down((2.0, 0.0, 3.3), (1280, 1280))
    both = CameraRig([CAM, other], [3.5, 3.5]).observe(frame)
    again = CameraRig([CAM, other], [3.5, 3.5]).observe(frame)
    alone = CameraRig([other], [3.5]).observe(frame)[0]
    assert [v.camera_index for v in both] == [0, 1]
    np.testing.assert_array_equal(both[0].boxes.xyxy, again[0].boxes.xyxy)
    np.testing.assert_array_equal(both[1].boxes.xyxy, alone.boxes.xyxy)


def test_an_empty_frame_gives_empty_views() -> None:
    views = CameraRig([CAM, CAM]).observe(people(np.zeros((0, 2))))
    assert [len(v) for v in views] == [0, 0] and [v.camera_index for v in views] == [0, 1]


def test_monitored_marks_points_inside_each_circle() -> None:
    rig = CameraRig([CAM, FisheyeCamera.looking_down((6.0, 0.0, 3.3), (640, 640))], [3.5, None])
    np.testing.assert_array_equal(rig.monitored(np.array([[3.0, 0.0], [3.6, 0.0]])), [[True, True], [False, True]])


def test_rig_needs_one_radius_per_camera() -> None:
    with pytest.raises(ValueError, match="2 monitored radii for 1 cameras"):
        CameraRig([CAM], [3.5, 3.5])


def test_clean_boxes_give_the_feet_back_through_the_cylinder_fit() -> None:
    """Smoke check against the cylinder fit: isolated, unoccluded people land near their feet."""
    cylinder = pytest.importorskip("bevflow.cylinder")
    frame = people([[0.8, 0.3], [-1.5, 1.2], [0.4, -2.6], [2.4, 1.9]], heading=[0.3, 2.0, -1.0, 1.5])
    view = one_view(frame)
    assert len(view) == 4
    fit = cylinder.fit_cylinders(CAM, view.boxes)
    err = np.linalg.norm(fit.xy - view.feet_xy, axis=1)
    assert np.all(err < 0.2), err


def test_leaving_the_monitored_area_and_coming_back_starts_a_new_track() -> None:
    gt = GroundTruthTracks(CameraRig([CAM], [3.5]))
    path = [[[1.0, 0.0], [0.0, 1.0]], [[3.0, 0.0], [0.0, 1.5]], [[4.0, 0.0], [0.0, 2.0]], [[3.0, 0.0], [0.0, 2.5]], []]
    seen = []
    for xy in path:
        frame = people(np.array(xy).reshape(-1, 2))
        truth = gt.update(frame)
        seen.append(dict(zip(truth.person_ids.tolist(), truth.track_ids.tolist(), strict=True)))
        np.testing.assert_array_equal(truth.feet_xy, frame.feet_xy[np.isin(frame.person_ids, truth.person_ids)])
    # Person 1 steps out at 4 m and back: track 1 ends, track 3 begins. Person 2 never leaves.
    assert seen == [{1: 1, 2: 2}, {1: 1, 2: 2}, {2: 2}, {1: 3, 2: 2}, {}]
