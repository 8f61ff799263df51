from __future__ import annotations

import math

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera
from bevflow.detect.scaling import scaled_focal
from bevflow.sim.bodies import BodyShape, Posture, pose_bodies
from bevflow.sim.render import Clutter, FisheyeRenderer, Room
from bevflow.sim.render_textures import Appearance, RenderStyle
from bevflow.sim.scene import Pillar, Shelf
from bevflow.sim.views import CameraRig

ROOM = Room(floor=(-8.0, -8.0, 8.0, 8.0), wall_height=4.0)


def _camera(height: float, fov: float = 185.0) -> FisheyeCamera:
    """A camera at the detector's scale: f = 40 (H - 1.4) px/rad."""
    f = scaled_focal(height)
    size = int(math.ceil(2 * f * math.radians(fov / 2)))
    return FisheyeCamera.looking_down((0.0, 0.0, height), (size, size), fov)


def _bodies(xy: list[tuple[float, float]], heading: float = 0.0, posture: Posture = Posture.STANDING):
    n = len(xy)
    return pose_bodies(BodyShape.standard(n), np.array(xy, dtype=float).reshape(n, 2), np.full(n, heading),
                       np.zeros(n), np.zeros(n), np.full(n, int(posture)))  # fmt: skip


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = w * h
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


@pytest.mark.parametrize("height", [3.3, 4.5, 6.0])
def test_person_below_the_camera_is_about_20_px_at_the_detector_scale(height: float) -> None:
    cam = _camera(height)
    out = FisheyeRenderer(cam, ROOM).render(_bodies([(0.0, 0.0)], heading=math.pi / 2), np.array([1]))
    (x0, y0, x1, y1) = out.boxes.xyxy[0]
    c = cam.K[0, 2]
    assert x0 < c < x1 and y0 < c < y1
    # Seen from straight above the widest part is the shoulders (0.259 x 1.72 m = 0.45 m, a bit
    # under the 0.5 m the scale assumes), at depth H - 1.4 m: about 18 px.
    across = max(x1 - x0, y1 - y0)
    assert 14.0 <= across <= 26.0


@pytest.mark.parametrize("xy", [(1.5, 0.5), (-2.0, 2.5), (3.0, -3.5)])
def test_box_agrees_with_the_visibility_model(xy: tuple[float, float]) -> None:
    cam = _camera(4.0)
    bodies = _bodies([xy])
    out = FisheyeRenderer(cam, ROOM).render(bodies, np.array([5]))
    frame_box = CameraRig([cam], [None]).observe(_FrameStub(bodies, xy))[0].boxes.xyxy[0]
    assert out.person_ids.tolist() == [5]
    assert _iou(out.boxes.xyxy[0], frame_box) > 0.75


class _FrameStub:
    """Just enough of a SceneFrame for CameraRig.observe."""

    def __init__(self, bodies, xy) -> None:  # noqa: ANN001
        self._bodies = bodies
        self.feet_xy = np.array([xy], dtype=float)
        self.person_ids = np.array([5])

    def __len__(self) -> int:
        return 1

    def primitives(self):  # noqa: ANN201
        return self._bodies


def test_a_pillar_between_camera_and_person_hides_them() -> None:
    cam = _camera(4.0)
    open_room = FisheyeRenderer(cam, ROOM).render(_bodies([(3.0, 0.0)]), np.array([1]))
    pillar_room = Room(ROOM.floor, 4.0, pillars=(Pillar(1.8, 0.0, 0.6, 4.0),))
    hidden = FisheyeRenderer(cam, pillar_room).render(_bodies([(3.0, 0.0)]), np.array([1]))
    assert len(open_room.boxes) == 1
    assert len(hidden.boxes) == 0


def test_a_nearer_person_cuts_the_box_of_the_one_behind() -> None:
    cam = _camera(3.3)
    alone = FisheyeRenderer(cam, ROOM).render(_bodies([(2.6, 0.0)]), np.array([2]))
    both = FisheyeRenderer(cam, ROOM).render(_bodies([(2.0, 0.0), (2.6, 0.0)]), np.array([1, 2]))
    far = both.person_ids.tolist().index(2)
    alone_area = np.prod(alone.boxes.xyxy[0, 2:] - alone.boxes.xyxy[0, :2])
    assert both.visible_fraction[far] < 0.9
    assert np.prod(both.boxes.xyxy[far, 2:] - both.boxes.xyxy[far, :2]) < alone_area
    assert (both.owner == 0).sum() > 0


def test_empty_room_is_black_outside_the_image_circle() -> None:
    cam = _camera(3.3)
    out = FisheyeRenderer(cam, ROOM).render(_bodies([]), np.zeros(0, np.int64))
    h, w = out.image.shape[:2]
    assert (h, w) == (cam.image_size[1], cam.image_size[0])
    assert len(out.boxes) == 0 and (out.owner == -1).all()
    assert out.image[0, 0].tolist() == [0, 0, 0]
    assert out.image[h // 2, w // 2].max() > 30  # the floor below the camera is lit


def test_window_is_the_same_crop_of_the_full_frame() -> None:
    cam = _camera(4.5)
    bodies = _bodies([(1.0, 1.0), (-2.0, 0.5)])
    room = Room(ROOM.floor, 4.0, shelves=(Shelf(2.0, -2.0, 3.0, -1.5, 1.5),), clutter=(Clutter(0.0, -1.5, 0.3, 0.2, 0.2),))
    full = FisheyeRenderer(cam, room).render(bodies, np.array([1, 2]))
    window = (60, 80, 200, 210)
    part = FisheyeRenderer(cam, room, window=window).render(bodies, np.array([1, 2]))
    x0, y0, x1, y1 = window
    np.testing.assert_array_equal(part.owner, full.owner[y0:y1, x0:x1])
    np.testing.assert_array_equal(part.image, full.image[y0:y1, x0:x1])
    assert part.origin == (60, 80)


def test_random_styles_render_and_keep_the_ground_truth() -> None:
    cam = _camera(4.0)
    bodies = _bodies([(1.0, 0.0)])
    renderer = FisheyeRenderer(cam, ROOM)
    plain = renderer.render(bodies, np.array([1]))
    for seed in range(3):
        rng = np.random.default_rng(seed)
        out = renderer.render(bodies, np.array([1]), Appearance.sample(rng, 1), RenderStyle.sample(rng), rng)
        assert out.image.dtype == np.uint8
        np.testing.assert_array_equal(out.boxes.xyxy, plain.boxes.xyxy)


def test_same_identity_same_clothes() -> None:
    a = Appearance.for_identities(np.array([3, 9]), seed=1)
    b = Appearance.for_identities(np.array([9]), seed=1)
    np.testing.assert_array_equal(a.top[1], b.top[0])
    assert not np.array_equal(a.top[0], a.top[1])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"window": (10, 10, 10, 20)}, "empty"), ({"window": (30, 10, 20, 20)}, "empty")],
)
def test_bad_windows_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        FisheyeRenderer(_camera(3.3), ROOM, **kwargs)


def test_appearance_must_match_the_bodies() -> None:
    renderer = FisheyeRenderer(_camera(3.3), ROOM)
    with pytest.raises(ValueError, match="appearance"):
        renderer.render(_bodies([(1.0, 0.0)]), np.array([1]), Appearance.sample(np.random.default_rng(0), 2))


def test_the_cached_static_scene_gives_the_same_frame_as_finishing_it_whole() -> None:
    # A style with no random faults is finished once for the static scene and then only where
    # people are; the same style with a tiny blur goes through the whole-frame path.
    cam = _camera(4.0)
    bodies = _bodies([(1.0, 0.0), (-1.5, 1.2), (0.3, -2.0)])
    renderer = FisheyeRenderer(cam, Room(ROOM.floor, 4.0, pillars=(Pillar(2.5, 2.5, 0.4, 4.0),)))
    fast = renderer.render(bodies, np.array([1, 2, 3]))
    style = RenderStyle.plain()
    whole = FisheyeRenderer(cam, renderer.room).render(bodies, np.array([1, 2, 3]), style=_with(style, blur_sigma_px=1e-9))
    np.testing.assert_array_equal(fast.owner, whole.owner)
    assert np.abs(fast.image.astype(int) - whole.image.astype(int)).max() <= 1


def test_a_renderer_reused_frame_after_frame_leaves_no_trace_of_earlier_people() -> None:
    cam = _camera(3.3)
    renderer = FisheyeRenderer(cam, ROOM)
    empty = renderer.render(_bodies([]), np.zeros(0, np.int64))
    renderer.render(_bodies([(0.5, 0.5), (-1.0, 0.0)]), np.array([1, 2]))
    again = renderer.render(_bodies([]), np.zeros(0, np.int64))
    np.testing.assert_array_equal(again.image, empty.image)
    assert (again.owner == -1).all()


def test_people_change_the_pixels_they_cover_and_only_those_and_their_shadow() -> None:
    cam = _camera(3.3)
    renderer = FisheyeRenderer(cam, ROOM)
    empty = renderer.render(_bodies([]), np.zeros(0, np.int64)).image
    out = renderer.render(_bodies([(1.0, 0.0)]), np.array([4]))
    changed = (out.image != empty).any(2)
    x0, y0, x1, y1 = out.boxes.xyxy[0]
    rows, cols = np.nonzero(changed)
    assert (out.owner == 0).sum() > 100
    assert changed[out.owner == 0].mean() > 0.9
    # Everything that changed lies near the person's box (the shadow reaches a little further).
    assert cols.min() > x0 - 15 and cols.max() < x1 + 15 and rows.min() > y0 - 15 and rows.max() < y1 + 15


def _with(style: RenderStyle, **changes: object) -> RenderStyle:
    from dataclasses import replace

    return replace(style, **changes)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_albedo_of_many_hits_matches_part_by_part(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Every kind of person: hat or hair, striped or plain top, sleeves and trousers or not.
    appearance = _with(Appearance.sample(rng, 6), hat=np.arange(6) % 2 == 0, stripes=np.where(np.arange(6) < 3, 30.0, 0.0),
                       sleeves=np.arange(6) % 3 == 0, trousers=np.arange(6) % 3 == 1)
    persons = rng.integers(0, 6, 400)
    parts = rng.integers(0, 14, 400)
    local = rng.normal(0, 0.6, (400, 3))
    many = appearance.albedo_of(persons, parts, local)
    pairs = enumerate(zip(persons.tolist(), parts.tolist(), strict=True))
    one_by_one = np.array([appearance.part_albedo(b, p, local[k : k + 1])[0] for k, (b, p) in pairs])
    np.testing.assert_allclose(many, one_by_one)
