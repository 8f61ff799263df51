from __future__ import annotations

import numpy as np
import pytest

from bevflow.detect.scaling import scaled_focal
from bevflow.sim.bodies import BodyShape
from bevflow.sim.render_feed import RenderedCameras, detector_frame_size
from bevflow.sim.scene import SceneConfig, SceneFrame
from bevflow.site import parse_site

SITE = parse_site("""
site: two
cameras:
  - {id: low, image_size: [1000, 1000], intrinsics: {fx: 318.3, fy: 318.3, cx: 499.5, cy: 499.5}, distortion: [0, 0, 0, 0], pose: {position: [0, 0, 3.3]}}
  - {id: high, image_size: [1200, 800], intrinsics: {fx: 500, fy: 500, cx: 599.5, cy: 399.5}, distortion: [0, 0, 0, 0], pose: {position: [4, 0, 8.1]}}
""")
SCENE = SceneConfig(floor=(-6.0, -6.0, 10.0, 6.0), people=0, frames=1)


def _frame(feet: list[tuple[float, float]], identity: list[int] | None = None) -> SceneFrame:
    n = len(feet)
    return SceneFrame(
        index=0, time_s=0.0, person_ids=np.arange(1, n + 1), identity=np.array(identity or list(range(n))),
        group=np.full(n, -1), feet_xy=np.array(feet, dtype=float).reshape(n, 2), heading=np.zeros(n),
        gait_phase=np.zeros(n), speed=np.zeros(n), posture=np.zeros(n, dtype=np.int64), body=BodyShape.standard(n),
    )  # fmt: skip


@pytest.mark.parametrize(("camera", "height"), [("low", 3.3), ("high", 8.1)])
def test_frames_are_rendered_at_the_detectors_scale(camera: str, height: float) -> None:
    cams = RenderedCameras(SITE, SCENE)
    w, h = cams.frame_size(camera)
    full_w, full_h = SITE.camera(camera).image_size
    assert (w, h) == detector_frame_size(SITE, camera)
    assert w / full_w == pytest.approx(scaled_focal(height) / SITE.camera(camera).K[0, 0], abs=1 / full_w)
    assert w / full_w == pytest.approx(h / full_h, abs=1 / full_h)
    image = cams.render(camera, _frame([])).image
    assert image.shape == (h, w, 3) and image.dtype == np.uint8


@pytest.mark.parametrize(("camera", "feet"), [("low", (1.0, 0.5)), ("high", (5.0, -1.0)), ("high", (2.0, 2.0))])
def test_a_person_is_where_the_calibrated_camera_sees_them(camera: str, feet: tuple[float, float]) -> None:
    cams = RenderedCameras(SITE, SCENE)
    out = cams.render(camera, _frame([feet]))
    assert out.person_ids.tolist() == [1]
    # Map the box back to the calibrated image, as the detector service does.
    s = cams.frame_size(camera)[0] / SITE.camera(camera).image_size[0]
    x0, y0, x1, y1 = (out.boxes.xyxy[0] + 0.5) / s - 0.5
    head = SITE.camera(camera).project(np.array([[feet[0], feet[1], 1.6]]))[0]
    assert x0 - 2 <= head[0] <= x1 + 2 and y0 - 2 <= head[1] <= y1 + 2


def test_a_person_looks_the_same_to_every_camera_and_every_frame() -> None:
    cams = RenderedCameras(SITE, SCENE)
    frame = _frame([(2.0, 0.0)], identity=[7])
    views = cams.render_all(frame)
    assert set(views) == {"low", "high"}
    colours = [v.image[v.owner == 0].mean(0) for v in views.values()]
    again = cams.render("low", frame)
    np.testing.assert_array_equal(again.image, views["low"].image)
    assert np.abs(colours[0] - colours[1]).max() < 40  # same clothes, seen at different scales


def test_only_the_chosen_cameras_get_renderers() -> None:
    cams = RenderedCameras(SITE, SCENE, cameras=["high"])
    assert cams.camera_ids == ["high"]
    with pytest.raises(KeyError):
        cams.frame_size("low")
