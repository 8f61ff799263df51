"""The tracker service's tick handling, without the bus: the cameras' messages go through the
same ``TickAssembler`` and ``TickHandler`` as live, and a camera turned by 2° half way through
comes out as a ``calibration_drift`` event on the events that ``main`` publishes.

The crowd and the per-camera estimates are those of the library's drift test
(``tests/bevflow/calibration/test_drift.py``): three 5.5 m ceiling fisheyes in a row; from the
change on, one camera's pixels come from a copy of it turned by 2°, while the site keeps the old
calibration.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from bevflow.calibration.drift import DriftConfig
from bevflow.camera import Camera
from bevflow.detections import Cylinders
from bevflow.live.assembler import TickAssembler
from bevflow.live.site_tracker import SiteTracker
from bevflow.schemas import CameraCylinders, decode_event
from bevflow.site import Site

from bevflow_services.runtime import UserError
from bevflow_services.tracker.main import add_arguments, drift_config
from bevflow_services.tracker.ticks import TickHandler
from tests.bevflow.calibration.test_drift import CONFIG, FPS, IDS, YAWS, feet_estimates, site_cameras, turned

PERIOD_NS = int(1e9 / FPS)
FRAMES, CHANGE = 750, 375  # five minutes; the bump half way


def site_of(cameras: list[Camera]) -> Site:
    configs = []
    for camera_id, camera in zip(IDS, cameras, strict=True):
        (fx, _, cx), (_, fy, cy), _ = camera.K
        configs.append({
            "id": camera_id,
            "model": "fisheye",
            "image_size": list(camera.image_size),
            "intrinsics": {"fx": fx, "fy": fy, "cx": cx, "cy": cy},
            "distortion": [float(v) for v in camera.dist],
            "extrinsics": {"rvec": [float(v) for v in camera.rvec], "tvec": [float(v) for v in camera.t]},
            "monitored_radius_m": 5.5,
        })
    return Site.model_validate({"site": "drift-hall", "cameras": configs})


def messages(estimates: list[Cylinders]) -> list[list[CameraCylinders]]:
    """Each frame's estimates as the projectors send them: per frame, one message per camera
    (captured a few microseconds apart, as unsynchronised cameras would)."""
    out = []
    for k, frame in enumerate(estimates):
        out.append([
            CameraCylinders.from_cylinders(camera_id, k, k * PERIOD_NS + 1000 * index, frame[frame.camera == index])
            for index, camera_id in enumerate(IDS)
        ])
    return out


def run_service_ticks(site: Site, frames: list[list[CameraCylinders]], drift: DriftConfig | None) -> tuple[list, int]:
    """Every message through the assembler and the handler, as ``main`` does; the events that
    would be published, with the index of the frame that raised each, and the number of ticks."""
    assembler: TickAssembler[CameraCylinders] = TickAssembler(IDS, period_ns=PERIOD_NS, max_wait_ns=PERIOD_NS // 2)
    handler = TickHandler(site, SiteTracker(site), drift)
    published, ticks = [], 0
    for k, frame in enumerate(frames):
        arrival = (k + 1) * PERIOD_NS  # the projectors' results arrive during the next frame
        for message in frame:
            assert assembler.push(message.camera, message.capture_ns, message, now_ns=arrival) == "accepted"
        for tick in assembler.pop_ready(now_ns=arrival):
            output = handler.handle(tick)
            ticks += 1
            assert sorted(tick.items) == IDS and output.tracks.time_ns == tick.time_ns
            published += [(tick.start_ns // PERIOD_NS, e) for e in output.events]
    return published, ticks


# The library's test turns each camera in several ways; here one is enough to show the wiring.
@pytest.mark.parametrize(("moved", "pitch_deg", "yaw_deg"), [(2, 2.0, 0.0)], ids=["end-tilted"])
def test_the_service_publishes_a_drift_event_naming_the_turned_camera(moved: int, pitch_deg: float, yaw_deg: float) -> None:
    cameras = site_cameras()
    true = list(cameras)
    true[moved] = turned(cameras[moved], YAWS[moved], pitch_deg, yaw_deg)
    site = site_of(cameras)
    estimates = feet_estimates(true, cameras, FRAMES, CHANGE, seed=moved + 10)
    published, ticks = run_service_ticks(site, messages(estimates), CONFIG)
    assert ticks == FRAMES
    drift = [(k, e) for k, e in published if e.type == "calibration_drift"]
    assert len(drift) == 1, drift
    frame, event = drift[0]
    assert (event.camera, event.end_ns) == (IDS[moved], None)
    assert CHANGE < frame < CHANGE + 120 * FPS  # within two minutes of the bump
    assert 0.10 < event.shift_m < 0.6
    assert event.raised_ns == event.start_ns  # the tick's capture time, for the alert's latency
    assert decode_event(event.model_dump_json()) == event  # what the events key carries


def test_no_drift_event_when_nothing_moves() -> None:
    cameras = site_cameras()
    still = messages(feet_estimates(cameras, cameras, FRAMES, 10**9, seed=3))
    published, ticks = run_service_ticks(site_of(cameras), still, CONFIG)
    assert ticks == FRAMES
    assert [e for _, e in published if e.type == "calibration_drift"] == []


def test_the_watch_can_be_turned_off() -> None:
    site = site_of(site_cameras())
    assert TickHandler(site, SiteTracker(site), drift=None).drift is None
    assert TickHandler(site, SiteTracker(site)).drift is not None  # on by default


def test_a_failing_drift_watch_does_not_stop_tracking() -> None:
    cameras = site_cameras()
    site = site_of(cameras)
    handler = TickHandler(site, SiteTracker(site), CONFIG)

    class Broken:
        def update(self, time_ns: int, cylinders: Cylinders) -> list:
            raise RuntimeError("boom")

    handler.drift = Broken()  # type: ignore[assignment]
    assembler: TickAssembler[CameraCylinders] = TickAssembler(IDS, period_ns=PERIOD_NS, max_wait_ns=0)
    person = Cylinders(xy=np.array([[8.5, 4.0]]))
    for index, camera_id in enumerate(IDS[:2]):
        assembler.push(camera_id, 1000, CameraCylinders.from_cylinders(camera_id, 0, 1000, person.with_camera(index)), now_ns=1000)
    (tick,) = assembler.flush()
    output = handler.handle(tick)
    assert handler.drift_errors == 1 and output.events == []
    assert output.tracks.time_ns == output.occupancy.time_ns == tick.time_ns == 1000  # the tick went through


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        ([], DriftConfig()),
        (["--drift-shift", "0.2", "--drift-warmup", "60", "--drift-window", "30"], DriftConfig(warmup_s=60, window_s=30, shift_m=0.2)),
        (["--no-drift"], None),
        (["--drift-shift", "0"], UserError),
        (["--drift-window", "0"], UserError),
    ],
)
def test_drift_flags(argv: list[str], expected: DriftConfig | None | type[Exception]) -> None:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(argv)
    if isinstance(expected, type):
        with pytest.raises(expected, match="--drift"):
            drift_config(args)
    else:
        assert drift_config(args) == expected
