from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bevflow.site import dump_site, load_site, load_site_or_builtin

from bevflow_services.benchmarks import live
from bevflow_services.benchmarks.live import hall_site, keeps_up, max_cameras


def test_four_cameras_stand_where_the_demo_halls_first_block_does() -> None:
    hall = load_site_or_builtin("demo-hall")
    expected = [c.pose.position for c in hall.cameras if c.id in ("hall-1", "hall-2", "hall-4", "hall-5")]
    site = hall_site(4)
    assert np.allclose([c.pose.position for c in site.cameras], expected)
    assert site.site == "bench-4" and [z.id for z in site.zones] == [z.id for z in hall.zones[:2]]


@pytest.mark.parametrize(("cameras", "cols", "rows"), [(4, 2, 2), (8, 3, 3), (12, 4, 3), (16, 4, 4)])
def test_more_cameras_extend_the_grid(cameras: int, cols: int, rows: int) -> None:
    site = hall_site(cameras)
    assert len(site.cameras) == cameras and len(set(site.camera_ids)) == cameras
    xs = {round(c.pose.position[0], 3) for c in site.cameras}
    ys = {round(c.pose.position[1], 3) for c in site.cameras}
    assert (len(xs), len(ys)) == (cols, rows)
    x0, y0, x1, y1 = site.floor
    assert all(x0 < c.pose.position[0] < x1 and y0 < c.pose.position[1] < y1 for c in site.cameras)


@pytest.mark.parametrize("cameras", [1, 2, 4, 5, 6, 8, 16, 32])
def test_every_camera_count_tried_makes_a_site_the_services_accept(cameras: int, tmp_path: Path) -> None:
    # The services read the site from a file, which is checked whole (zones on the floor, ...).
    path = tmp_path / "bench.yaml"
    path.write_text(dump_site(hall_site(cameras)))
    site = load_site(path)
    assert len(site.cameras) == cameras and site.zones  # at least the first zone stays on the floor


def run(**changes: object) -> dict:
    base = {"cameras": 4, "people": 30, "duration_s": 10.0, "services_died": [], "frames_published": 100,
            "frames_dropped_at_source": 0, "tracks_latency_p99_ms": 60.0, "tracks_messages": 100}
    return base | changes


@pytest.mark.parametrize(
    ("changes", "ok", "why"),
    [
        ({}, True, "kept up"),
        ({"frames_dropped_at_source": 3}, False, "3 frames dropped at the source"),
        ({"tracks_latency_p99_ms": 151.0}, False, "tracks latency p99 151 ms > 150 ms"),
        ({"tracks_latency_p99_ms": math.nan}, False, "tracks latency p99"),
        ({"tracks_messages": 80}, False, "80 ticks delivered in 10 s"),
        ({"frames_published": 0}, False, "no frame was published"),
        ({"services_died": ["tracker"]}, False, "services exited: tracker"),
        # recorded cameras: no drops at the source to count, the detector's skipped frames instead
        ({"boxes": "recorded", "frames_dropped_at_source": None, "frames_published": None,
          "frames_detected": 400, "frames_skipped_by_detector": 2}, True, "kept up"),
        ({"boxes": "recorded", "frames_dropped_at_source": None, "frames_published": None,
          "frames_detected": 400, "frames_skipped_by_detector": 40}, False, "the detector skipped 40 of 440 frames"),
    ],
)
def test_keeps_up(changes: dict, ok: bool, why: str) -> None:
    verdict, reason = keeps_up(run(**changes))
    assert verdict is ok and why in reason


@pytest.mark.parametrize(
    ("limit", "steps", "bisect", "best", "lower_bound", "probed"),
    [
        (12, [4, 8, 16], True, 12, False, [4, 8, 16, 12]),
        (10, [4, 8, 16], True, 8, False, [4, 8, 16, 12]),
        (100, [4, 8, 16], True, 16, True, [4, 8, 16]),
        (3, [4, 8], True, None, False, [4]),
        (10, [4, 8, 16], False, 8, False, [4, 8, 16]),
    ],
)
def test_max_cameras_search(monkeypatch: pytest.MonkeyPatch, limit: int, steps: list[int], bisect: bool,
                            best: int | None, lower_bound: bool, probed: list[int]) -> None:
    # A machine that keeps up with at most ``limit`` cameras; ``first`` is reused for 4 cameras.
    asked: set[str] = set()

    def fake_measure(duration_s: float, people: object, warmup_s: float, cameras: int, boxes: str = "simulated") -> dict:
        asked.add(boxes)
        return run(cameras=cameras, frames_dropped_at_source=0 if cameras <= limit else 5)

    monkeypatch.setattr(live, "measure", fake_measure)
    first = fake_measure(1.0, None, 0.0, 4)
    asked.clear()
    result = max_cameras(steps, 1.0, 0.0, first=first, bisect=bisect, boxes="rendered")
    assert asked <= {"rendered"}
    assert result["max_cameras"] == best and result["lower_bound_only"] is lower_bound
    assert [p["cameras"] for p in result["probes"]] == probed


def test_detection_log_counts_frames_the_detector_skipped_and_their_age() -> None:
    from bevflow.schemas import Detections2D

    log = live.DetectionLog()
    now = __import__("time").time_ns()
    log.on_detections(Detections2D(camera="a", seq=1, capture_ns=now))  # before recording: ignored
    log.recording = True
    for camera, seqs in {"a": [3, 4, 7], "b": [10, 12]}.items():
        for seq in seqs:
            log.on_detections(Detections2D(camera=camera, seq=seq, capture_ns=now - 50_000_000))
    summary = log.summary()
    assert summary["frames_detected"] == 5
    assert summary["frames_skipped_by_detector"] == 2 + 1  # a: 5, 6; b: 11
    assert 50.0 <= summary["detections_latency_p50_ms"] < 5000.0
