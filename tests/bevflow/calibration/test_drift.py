"""Drift detection: a camera rotated by 2° mid-run is named, and nothing is named when none moves.

Three 5.5 m ceiling fisheyes in a row (a – b – c, each overlapping its neighbours) watch a
simulated crowd. The site keeps the original calibration; from the change on, the pixels come from
a copy of one camera turned by 2°. The fast tests place each person's feet through the true camera
and back through the site's (plus per-person bias and per-frame noise like a cylinder fit's); the
slow one runs the full chain (bodies, visibility, boxes, cylinder fit).
"""

from __future__ import annotations

import functools
from collections.abc import Iterable

import numpy as np
import pytest

from bevflow.calibration.drift import DriftConfig, DriftMonitor, _explain
from bevflow.camera import Camera, FisheyeCamera, rotation_from_ypr
from bevflow.cylinder import fit_cylinders
from bevflow.detections import Cylinders
from bevflow.schemas import CalibrationDrift, decode_event
from bevflow.sim.scene import Scene, SceneConfig
from bevflow.sim.views import CameraRig

IDS = ["a", "b", "c"]
HEIGHT_M = 5.5
XS = (4.0, 13.0, 22.0)
YAWS = (0.0, 30.0, 60.0)
RADIUS_M = 5.5
FLOOR = (0.0, 0.0, 26.0, 8.0)
FPS = 2.5
CONFIG = DriftConfig(warmup_s=60.0, window_s=45.0, min_samples=30, shift_m=0.10)


def site_cameras(size: int = 640) -> list[Camera]:
    return [FisheyeCamera.looking_down((x, 4.0, HEIGHT_M), (size, size), 185.0, yaw) for x, yaw in zip(XS, YAWS, strict=True)]


def turned(camera: Camera, yaw: float, pitch_deg: float, yaw_deg: float) -> Camera:
    """The same camera, still hanging at the same place, turned by a bump."""
    R = rotation_from_ypr(yaw + yaw_deg, pitch_deg, 0.0)
    return camera.with_pose(R, -R @ camera.center)


def scene(frames: int, seed: int, fps: float = FPS) -> Scene:
    config = SceneConfig(
        floor=FLOOR, identities=None, people=30, frames=frames, seed=seed, fps=fps, group_fraction=0.0, standing_fraction=0.0
    )
    return Scene(config)


@functools.lru_cache(maxsize=2)
def crowd(frames: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every frame's people at once: frame index, visit id and feet (rows of all frames)."""
    rows = [(np.full(len(f), f.index), f.person_ids, f.feet_xy) for f in scene(frames, seed)]
    return tuple(np.concatenate(column) for column in zip(*rows, strict=True))  # type: ignore[return-value]


def feet_estimates(true: list[Camera], site: list[Camera], frames: int, change: int, seed: int) -> list[Cylinders]:
    """Per frame, every camera's estimate of the feet it covers: the true camera's pixel of the
    feet, placed on the floor by the site's camera, plus a per-person bias (0.08 m) and per-frame
    noise (0.04 m), about what the cylinder fit shows."""
    frame, person, feet_xy = crowd(frames, seed=3)
    rng = np.random.default_rng(seed)
    parts = []
    for i, (site_cam, true_cam) in enumerate(zip(site, true, strict=True)):
        bias = rng.normal(0.0, 0.08, (int(person.max()) + 1, 2))
        inside = np.linalg.norm(feet_xy - site_cam.center[:2], axis=1) <= RADIUS_M
        feet = np.column_stack([feet_xy[inside], np.zeros(int(inside.sum()))])
        late = frame[inside] >= change
        pixels = site_cam.project(feet)
        pixels[late] = true_cam.project(feet[late])
        xy = site_cam.pixels_to_plane(pixels, 0.0)[:, :2] + bias[person[inside]] + rng.normal(0.0, 0.04, (len(feet), 2))
        parts.append((frame[inside], Cylinders(xy=xy, camera=np.full(len(xy), i))))
    out = []
    for k in range(frames):
        out.append(Cylinders.merge([c[at == k] for at, c in parts]))
    return out


def run_monitor(estimates: Iterable[Cylinders]) -> list[tuple[int, CalibrationDrift]]:
    monitor = DriftMonitor(IDS, CONFIG)
    out = []
    for k, cylinders in enumerate(estimates):
        out += [(k, e) for e in monitor.update(int(k * 1e9 / FPS), cylinders)]
    return out


@pytest.mark.parametrize(
    ("moved", "pitch_deg", "yaw_deg"),
    [(1, 2.0, 0.0), (0, 2.0, 0.0), (2, 0.0, 2.0), (1, 0.0, -2.0)],
    ids=["middle-tilted", "end-tilted", "end-turned", "middle-turned"],
)
def test_a_camera_turned_by_two_degrees_is_named(moved: int, pitch_deg: float, yaw_deg: float) -> None:
    site = site_cameras()
    true = list(site)
    true[moved] = turned(site[moved], YAWS[moved], pitch_deg, yaw_deg)
    frames, change = 750, 375  # 5 minutes, the bump half way
    events = run_monitor(feet_estimates(true, site, frames, change, seed=moved + 10))
    assert len(events) == 1, events
    frame, event = events[0]
    assert event.camera == IDS[moved] and event.end_ns is None
    assert change < frame < change + 120 * FPS  # found within two minutes
    assert 0.10 < event.shift_m < 0.6
    assert event.reference_camera in IDS and event.reference_camera != event.camera
    assert decode_event(event.model_dump_json()) == event  # a valid wire message


def test_no_event_when_nothing_moves() -> None:
    site = site_cameras()
    assert run_monitor(feet_estimates(site, site, 750, 10**9, seed=3)) == []


def test_event_ends_when_the_camera_is_put_back_and_reset_forgets() -> None:
    site = site_cameras()
    true = list(site)
    true[1] = turned(site[1], YAWS[1], 2.5, 0.0)
    monitor = DriftMonitor(IDS, CONFIG)
    moved_frames = range(250, 500)  # bumped, then put back as it was
    estimates_before = feet_estimates(true, site, 750, 250, seed=4)
    estimates_back = feet_estimates(site, site, 750, 0, seed=4)
    events = []
    for k, (bumped, back) in enumerate(zip(estimates_before, estimates_back, strict=True)):
        events += monitor.update(int(k * 1e9 / FPS), bumped if k in moved_frames else back)
    assert [(e.camera, e.end_ns is None) for e in events] == [("b", True), ("b", False)]
    assert events[0].id == events[1].id and events[1].end_ns > events[1].start_ns
    assert monitor.active == []
    monitor.reset("b")
    assert [p.camera_a + p.camera_b for p in monitor.pairs()] == []  # both pairs include b


@pytest.mark.parametrize(
    ("shifts", "expected"),
    [
        ({(0, 1): 0.3, (1, 2): 0.4}, {1: (1, 2)}),  # both pairs of the middle camera
        ({(0, 1): 0.3, (1, 2): 0.01}, {0: (0, 1)}),  # b's other pair is stable: a moved
        ({(0, 1): 0.3, (1, 2): 0.07}, {}),  # a or b? wait until b's other pair settles
        ({(0, 1): 0.3}, {1: (0, 1)}),  # two cameras alone: the later is named
        ({(0, 1): 0.02, (1, 2): 0.03}, {}),
        ({(0, 1): 0.3, (0, 2): 0.4, (1, 2): 0.01}, {0: (0, 2)}),  # a triangle, a moved
        ({(0, 1): 0.3, (2, 3): 0.3, (1, 2): 0.0}, {0: (0, 1), 3: (2, 3)}),  # two cameras at once
    ],
)
def test_blame(shifts: dict[tuple[int, int], float], expected: dict[int, tuple[int, int]]) -> None:
    assert _explain(shifts, shift_m=0.1) == expected


@pytest.mark.parametrize(
    "options",
    [{"warmup_s": -1.0}, {"window_s": 0.0}, {"min_samples": 0}, {"shift_m": 0.0}, {"shift_m": 1.2, "pair_gate_m": 1.0}, {"evaluate_every_s": -1.0}],
)
def test_bad_config(options: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        DriftConfig(**options)  # type: ignore[arg-type]


@pytest.mark.slow
def test_full_simulation_names_the_tilted_camera() -> None:
    """Bodies, visibility and cylinder fits at 5 fps, with the middle camera tilted by 2° at 110 s."""
    site = site_cameras()
    true = list(site)
    true[1] = turned(site[1], YAWS[1], 2.0, 0.0)
    before = CameraRig(site, [RADIUS_M] * 3, points_per_body=64)
    after = CameraRig(true, [RADIUS_M] * 3, points_per_body=64)
    monitor = DriftMonitor(IDS, DriftConfig(warmup_s=60.0, window_s=40.0, min_samples=30, shift_m=0.10))
    change, events = 550, []
    for frame in scene(1000, seed=3, fps=5.0):
        views = (before if frame.index < change else after).observe(frame)
        cylinders = Cylinders.merge([fit_cylinders(site[i], v.boxes, camera_index=i) for i, v in enumerate(views)])
        events += [(frame.index, e) for e in monitor.update(int(frame.index * 2e8), cylinders)]
    assert [e.camera for _, e in events] == ["b"]
    assert events[0][0] > change


def test_doctests() -> None:
    import doctest

    import bevflow.calibration.drift

    assert doctest.testmod(bevflow.calibration.drift).failed == 0
