from __future__ import annotations

import math

import numpy as np
import pytest

import bevflow.live.site_tracker as site_tracker_module
from bevflow.live.site_tracker import SiteTracker
from bevflow.site import Thresholds

from bevflow_services.benchmarks.tracking import (
    CAMERA_SPACING_M,
    MONITORED_RADIUS_M,
    bench_tick,
    grid_site,
    main,
    observe,
    stage_clock,
    walk,
    with_projector_covariance,
)


@pytest.mark.parametrize(("cameras", "cols", "rows"), [(1, 1, 1), (4, 2, 2), (6, 3, 2), (16, 4, 4), (64, 8, 8)])
def test_grid_site_lays_cameras_in_a_near_square_grid(cameras: int, cols: int, rows: int) -> None:
    site = grid_site(cameras, people=100)
    assert len(site.cameras) == cameras
    assert site.floor == (0.0, 0.0, cols * CAMERA_SPACING_M, rows * CAMERA_SPACING_M)
    xs = sorted({c.pose.position[0] for c in site.cameras})
    assert np.allclose(np.diff(xs), CAMERA_SPACING_M)
    assert site.thresholds.site_capacity == 100 and len(site.zones) == 4


def test_every_point_of_a_full_grid_is_seen_by_one_to_four_cameras() -> None:
    site = grid_site(16, people=10)
    centres = np.array([c.pose.position[:2] for c in site.cameras])
    g = np.linspace(0.0, 4 * CAMERA_SPACING_M, 60)
    points = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    views = (np.linalg.norm(points[:, None] - centres[None], axis=2) < MONITORED_RADIUS_M).sum(axis=1)
    assert views.min() >= 1 and views.max() <= 4
    assert 1.6 < views.mean() < 2.6  # "two on average", as the module says


def test_walkers_stay_on_the_floor_and_move_at_walking_speed() -> None:
    floor = (0.0, 0.0, 20.0, 10.0)
    xy = walk(50, 100, floor, np.random.default_rng(1))
    assert xy.shape == (100, 50, 2)
    assert xy[..., 0].min() >= 0 and xy[..., 0].max() <= 20 and xy[..., 1].min() >= 0 and xy[..., 1].max() <= 10
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=2) * 10  # 10 ticks a second
    assert np.median(speed) == pytest.approx(1.3, abs=0.2)


def test_each_camera_reports_only_the_people_inside_its_circle() -> None:
    site = grid_site(4, people=2)
    centre = np.array(site.cameras[0].pose.position[:2])
    truth = np.array([centre + [1.0, 0.0], centre + [-30.0, -30.0]])  # the second is outside every circle
    seen = {cam: 0 for cam in site.camera_ids}
    rng = np.random.default_rng(0)
    for _ in range(40):
        for cam, cylinders in observe(site, truth, rng).items():
            near = np.linalg.norm(cylinders.xy - truth[0], axis=1) < 0.5
            seen[cam] += int(near.any())
            assert not (np.linalg.norm(cylinders.xy - truth[1], axis=1) < 0.5).any()
    distance = {c.id: math.dist(c.pose.position[:2], truth[0]) for c in site.cameras}
    for cam, count in seen.items():
        if distance[cam] < MONITORED_RADIUS_M:
            assert count >= 32  # 5 % missed, over 40 ticks
        else:
            assert count <= 2  # only a false positive could land there


def test_the_bench_site_tracks_as_a_site_does_by_default() -> None:
    assert grid_site(4, people=10).thresholds.track_hypotheses == Thresholds().track_hypotheses > 1


@pytest.mark.parametrize("hypotheses", [1, 5])
def test_bench_tick_reports_finite_numbers_and_every_stage(hypotheses: int) -> None:
    assert grid_site(4, people=10, hypotheses=hypotheses).thresholds.track_hypotheses == hypotheses
    row = bench_tick(people=10, cameras=4, ticks=3, warmup=4, hypotheses=hypotheses)
    for key in ("ms_p50", "ms_p95", "cpu_ms_p50", "cylinders_per_tick", "MOTA", "IDF1"):
        assert math.isfinite(row[key]), key
    assert set(row["stage_cpu_ms_p50"]) == {"fusion", "tracker", "analytics", "rest"}
    assert all(v >= 0 for k, v in row["stage_cpu_ms_p50"].items() if k != "rest")
    assert row["MOTA"] > 0.5  # ten walkers seen twice over: the tick timed does track them


def test_stage_clock_times_the_stages_and_puts_everything_back() -> None:
    site = grid_site(4, people=5)
    tracker = SiteTracker(site)
    fuse, update = site_tracker_module.fuse_cylinders, tracker.tracker.update
    per_camera = observe(site, np.array([[5.0, 5.0], [12.0, 14.0]]), np.random.default_rng(0))
    with stage_clock(tracker) as clock:
        tracker.step(0, per_camera)
        tracker.step(100_000_000, per_camera)
    assert {k: len(v) for k, v in clock.seconds.items()} == {"fusion": 2, "tracker": 2, "analytics": 2}
    assert site_tracker_module.fuse_cylinders is fuse
    assert "update" not in vars(tracker.tracker) and tracker.tracker.update == update


def test_covariances_from_the_projector_track_exactly_as_those_fusion_computes() -> None:
    rows = {source: bench_tick(people=30, cameras=4, ticks=4, warmup=4, covariance=source) for source in ("projector", "fusion")}
    assert rows["projector"]["covariance"] == "projector" and rows["fusion"]["covariance"] == "fusion"
    for key in ("MOTA", "IDF1", "open_violations_per_tick", "events_per_tick", "cylinders_per_tick"):
        assert rows["projector"][key] == rows["fusion"][key], key


def test_projector_covariance_is_attached_to_every_camera() -> None:
    site = grid_site(4, people=5)
    per_camera = observe(site, np.array([[5.0, 5.0], [12.0, 14.0]]), np.random.default_rng(0))
    carried = with_projector_covariance(site, per_camera)
    assert carried.keys() == per_camera.keys()
    for camera, cylinders in carried.items():
        assert cylinders.covariance.shape == (len(per_camera[camera]), 2, 2)
        np.testing.assert_array_equal(cylinders.camera, site.camera_index(camera))


def test_bench_tick_refuses_an_unknown_covariance_source() -> None:
    with pytest.raises(ValueError, match="covariance must be one of"):
        bench_tick(people=5, cameras=4, ticks=1, warmup=1, covariance="nowhere")


def test_hypotheses_outside_the_site_files_range_are_refused(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["--hypotheses", "0"])
    assert "--hypotheses must be a whole number from 1 to 100, got 0" in capsys.readouterr().err
