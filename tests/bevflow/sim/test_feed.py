from __future__ import annotations

import itertools

import numpy as np
import pytest

from bevflow.sim.feed import SimulatedFeed, scene_for_site
from bevflow.sim.noise import DetectorNoise
from bevflow.sim.presets import demo_hall
from bevflow.site import BUILTIN_SITES, load_site, load_site_or_builtin, parse_site

SMALL_SITE = """
site: small-room
cameras:
  - {id: a, image_size: [640, 640], intrinsics: {fx: 200, fy: 200, cx: 319.5, cy: 319.5}, distortion: [0, 0, 0, 0],
     pose: {position: [3, 3, 3.3]}, monitored_radius_m: 3.5}
"""


def test_the_shipped_demo_site_is_the_demo_preset() -> None:
    # Regenerate with: python -c "from bevflow.sim.presets import demo_hall; ..." (see the file's header).
    assert load_site(BUILTIN_SITES / "demo-hall.yaml") == demo_hall().site


def test_a_builtin_site_gets_its_preset_crowd_without_end() -> None:
    preset = scene_for_site(load_site_or_builtin("demo-hall"), people=7, seed=3)
    assert preset.scene.frames is None and preset.scene.people == 7 and preset.scene.seed == 3
    assert preset.scene.pillars == demo_hall().scene.pillars


def test_any_other_site_gets_doors_on_the_walls_of_its_coverage() -> None:
    preset = scene_for_site(parse_site(SMALL_SITE))
    assert preset.scene.floor == pytest.approx((-0.5, -0.5, 6.5, 6.5))
    assert len(preset.scene.entries) == 4 and preset.scene.frames is None


def test_frames_carry_noisy_detections_per_camera_and_the_truth() -> None:
    feed = SimulatedFeed(scene_for_site(load_site_or_builtin("demo-hall"), people=20), DetectorNoise(), seed=0)
    frames = list(itertools.islice(feed, 3))
    assert [f.index for f in frames] == [0, 1, 2]
    assert all(len(f.detections) == 9 for f in frames)
    last = frames[-1]
    assert len(last.truth.track_ids) > 0
    assert sum(len(b) for b in last.detections) >= len(last.truth.track_ids)  # overlaps see people twice


def test_the_feed_is_deterministic_and_observing_is_separable() -> None:
    site = load_site_or_builtin("demo-hall")
    a = list(itertools.islice(SimulatedFeed(scene_for_site(site, people=10)), 4))
    feed = SimulatedFeed(scene_for_site(site, people=10))
    b = [feed.observe(frame, truth) for frame, truth in itertools.islice(feed.scene_frames(), 4)]
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.truth.feet_xy, y.truth.feet_xy)
        for bx, by in zip(x.detections, y.detections, strict=True):
            np.testing.assert_array_equal(bx.xyxy, by.xyxy)
