from __future__ import annotations

import numpy as np
import pytest

from bevflow_services.benchmarks.cylinder import MONITORED_RADIUS_M, bench_speed, make_camera, random_feet, silhouette_boxes


def test_people_stand_within_the_monitored_radius() -> None:
    camera = make_camera("fisheye-3.3")
    feet = random_feet("fisheye-3.3", camera, 500, np.random.default_rng(0))
    assert np.linalg.norm(feet - camera.center[:2], axis=1).max() <= MONITORED_RADIUS_M["fisheye-3.3"]


def test_silhouette_boxes_lie_in_the_image_and_around_the_feet() -> None:
    camera = make_camera("fisheye-5.5")
    rng = np.random.default_rng(0)
    feet = random_feet("fisheye-5.5", camera, 20, rng)
    boxes = silhouette_boxes(camera, feet, rng)
    w, h = camera.image_size
    assert (boxes >= 0).all() and (boxes[:, [0, 2]] <= w - 1).all() and (boxes[:, [1, 3]] <= h - 1).all()
    feet_px = camera.project(np.c_[feet, np.zeros(len(feet))])
    inside = (feet_px >= boxes[:, :2] - 1) & (feet_px <= boxes[:, 2:] + 1)
    assert inside.all()


@pytest.mark.parametrize(("sizes", "cap", "checked"), [([6], None, [6]), ([3, 8], 5, [3, 5])])
def test_bench_speed_agrees_with_the_reference(sizes: list[int], cap: int | None, checked: list[int]) -> None:
    rows = bench_speed("fisheye-3.3", sizes, repeats=2, reference_repeats=1, reference_max_boxes=cap)
    assert [r["boxes"] for r in rows] == sizes
    assert [r["reference_boxes"] for r in rows] == checked
    for r in rows:
        assert r["max_disagreement_m"] < 0.01 and r["nan_mismatches"] == 0
        assert r["batched_ms_per_box"] > 0 and r["reference_ms_per_box"] > 0
        assert r["speedup"] > 1  # the reference is the slow oracle
