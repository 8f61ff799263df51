from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bevflow.datasets.mot import WorldTruth
from bevflow.detections import Cylinders
from bevflow.evaluation.camera_errors import MIN_MOVING, CameraErrorSamples
from tests.bevflow.datasets.test_wildtrack import fake_cameras
from tests.bevflow.evaluation.test_replay import replay, write_recording
from tests.bevflow.evaluation.test_wildtrack_tracking import walkers

FPS = 4.0
SPEED = np.array([0.8, -0.3])  # everyone's velocity, m/s


def walking_truth(frames: int) -> WorldTruth:
    """Four people walking at ``SPEED`` in front of the fake cameras, frame f at f / ``FPS`` s."""
    starts = np.array([[3.0, -1.5], [4.0, 0.5], [5.0, -0.5], [6.0, 1.5]])
    ids = np.arange(1, len(starts) + 1)
    return WorldTruth({f: (ids, starts + SPEED * f / FPS) for f in range(frames)})


def views_of(truth_xy: np.ndarray, centre: np.ndarray, turn_rad: float, beyond_m: float, lag_s: float) -> Cylinders:
    """What a camera at ``centre`` reports of people at ``truth_xy``: where they will be ``lag_s``
    later, ``beyond_m`` farther along its line of sight, and turned ``turn_rad`` about it."""
    moved = truth_xy + SPEED * lag_s
    sight = moved - centre
    sight = sight * (1.0 + beyond_m / np.linalg.norm(sight, axis=1))[:, None]
    c, s = math.cos(turn_rad), math.sin(turn_rad)
    turned = sight @ np.array([[c, s], [-s, c]])  # row vectors: anticlockwise by turn_rad
    return Cylinders(xy=centre + turned, camera=np.zeros(len(truth_xy), dtype=np.int64))


@pytest.mark.parametrize(
    ("turn_mrad", "beyond_m", "lag_s"),
    [(0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (-15.0, 0.1, 0.0), (0.0, -0.2, 0.0), (0.0, 0.0, 0.1), (0.0, 0.0, -0.08)],
)
def test_each_camera_error_is_read_back_with_its_sign(turn_mrad: float, beyond_m: float, lag_s: float) -> None:
    truth = walking_truth(12)
    camera = fake_cameras()[0]
    samples = CameraErrorSamples(["cam"], [camera], truth, FPS)
    for frame in truth.frame_numbers:
        samples.add(frame, {"cam": views_of(truth.at(frame)[1], camera.center[:2], turn_mrad / 1e3, beyond_m, lag_s)})
    (got,) = samples.errors()
    assert got.camera_id == "cam" and got.views == 4 * 12 and got.lag_s is not None
    if lag_s:  # everyone walks one way here, so a lag shows in the bearing and range too: only it is read
        assert got.lag_s == pytest.approx(lag_s, abs=1e-6)
    else:  # a turn moves a view across by its chord, and back along its line of sight by a hair
        assert got.across_mrad == pytest.approx(turn_mrad, abs=0.05 * abs(turn_mrad) + 1e-6)
        assert got.along_m == pytest.approx(beyond_m, abs=5e-3)
        assert got.across_spread_mrad < 1.0 and got.along_spread_m < 5e-3


def test_no_lag_without_enough_moving_people_and_nan_without_matches() -> None:
    still = WorldTruth({f: (np.array([1]), np.array([[4.0, 0.0]])) for f in range(MIN_MOVING + 5)})
    cameras = fake_cameras()
    samples = CameraErrorSamples(["seen", "blind"], cameras, still, FPS)
    for frame in still.frame_numbers:
        samples.add(frame, {"seen": Cylinders(xy=[[4.05, 0.0]], camera=[0]), "blind": Cylinders(xy=[[9.0, 9.0]], camera=[1])})
    seen, blind = samples.errors()
    assert seen.views == MIN_MOVING + 5 and seen.lag_s is None and math.isfinite(seen.across_mrad)
    assert blind.views == 0 and math.isnan(blind.across_mrad) and blind.lag_s is None  # 9 m off: matches nobody


def test_a_replay_names_the_camera_whose_boxes_come_a_frame_late(tmp_path: Path) -> None:
    write_recording(walkers(0.2, hidden=None, ghost=None), tmp_path)  # 0.4 m/s: a frame late is 0.2 m off
    on_time = replay(tmp_path).cameras
    late = tmp_path / "detections" / "CVLab2.txt"
    rows = [line.split(",", 1) for line in late.read_text().splitlines()]
    late.write_text("".join(f"{int(frame) + 1},{rest}\n" for frame, rest in rows))  # frame k's boxes shown at k + 1
    result = replay(tmp_path)
    first, second = result.cameras
    assert [c.camera_id for c in on_time] == ["CVLab1", "CVLab2"] and all(c.views == 24 for c in on_time)
    assert all(abs(c.across_mrad) < 5 for c in on_time)  # calibrated cameras: bearings right
    assert first == on_time[0]
    # Only differences of lags mean anything (the fit's range bias has a part along the walk too).
    assert second.views == 21 and on_time[1].lag_s is not None and second.lag_s is not None  # frame 0: no boxes
    assert second.lag_s - on_time[1].lag_s == pytest.approx(-0.5, abs=0.05)  # a frame is 0.5 s here
    assert result.as_dict()["cameras"][1]["lag_s"] == second.lag_s


def test_a_person_right_below_a_camera_and_a_camera_without_strong_views_are_passed_over() -> None:
    camera = fake_cameras()[0]
    below = camera.center[:2]
    truth = WorldTruth({0: (np.array([1, 2]), np.array([below, [4.0, 0.0]]))})
    samples = CameraErrorSamples(["cam", "weak"], [camera, camera], truth, FPS)
    samples.add(0, {"cam": Cylinders(xy=[below, [4.0, 0.1]], camera=[0, 0]),
                    "weak": Cylinders(xy=[[4.0, 0.0]], camera=[0], score=[0.0])})  # fmt: skip
    cam, weak = samples.errors()
    assert cam.views == 1 and np.isfinite([cam.across_mrad, cam.along_m]).all()
    assert weak.views == 0
