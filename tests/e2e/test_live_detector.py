"""The live system with the person detector in the loop: rendered camera frames in (ingest →
detector → projector → tracker → gateway, plus the history recorder), REST occupancy out, checked
against the simulator's ground truth; garbage frames on the bus do not stop the detector."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from bevflow.schemas import FrameHeader, SimulatedTruth
from bevflow.site import dump_site, load_site_or_builtin

from bevflow_services import bus
from bevflow_services.launcher import ServiceGroup, free_port, start_pipeline
from tests.e2e.http import get_json

pytestmark = pytest.mark.e2e
PEOPLE = 8
SITE_ID = "e2e-detector"
SERVED = ("hall-1", "hall-2")
SPARE = "spare"


def two_camera_hall() -> str:
    """The west end of the demo hall: two of its 5.5 m fisheyes, 13.3 m apart, and the gate zone."""
    hall = load_site_or_builtin("demo-hall")
    # A third camera far from the floor, which the ingest does not serve: only the test's
    # garbage reaches the detector on its key (on a served camera, real frames would overwrite
    # the garbage before the detector read it: latest frame wins).
    spare = hall.cameras[2].model_copy(update={
        "id": SPARE, "monitored_radius_m": 0.5,
        "pose": hall.cameras[2].pose.model_copy(update={"position": (200.0, 200.0, 5.5)})})
    site = hall.model_copy(update={"site": SITE_ID, "cameras": [*hall.cameras[:2], spare], "zones": hall.zones[:1],
                                   "floor": (0.0, 0.0, 26.7, 8.4)})
    return dump_site(site)


class TruthLog:
    def __init__(self, group: ServiceGroup) -> None:
        cfg = bus.BusConfig(mode="peer", listen=("tcp/127.0.0.1:0",), connect=(f"tcp/127.0.0.1:{group.hub_port}",))
        self.session = bus.open_session(cfg)
        self.counts: dict[int, int] = {}
        self.lock = threading.Lock()
        self.subscription = bus.subscribe(self.session, bus.Keys(SITE_ID).truth, bus.JsonCodec(SimulatedTruth), self._on)

    def _on(self, truth: SimulatedTruth) -> None:
        with self.lock:
            self.counts[truth.capture_ns] = len(truth.tracks)

    def count_at(self, time_ns: int) -> int | None:
        with self.lock:
            if not self.counts:
                return None
            nearest = min(self.counts, key=lambda t: abs(t - time_ns))
            return self.counts[nearest] if abs(nearest - time_ns) < 60_000_000 else None

    def close(self) -> None:
        self.subscription.close()
        self.session.close()


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory):
    folder = Path(tmp_path_factory.mktemp("detector-e2e"))
    site_path = folder / "site.yaml"
    site_path.write_text(two_camera_hall())
    group = ServiceGroup(site=str(site_path), log_dir=folder / "logs")
    try:
        base = start_pipeline(group, free_port(), ingest_args=("--people", str(PEOPLE), "--cameras", ",".join(SERVED)),
                              gateway_args=("--no-view3d",),
                              detector_args=("--threads", "1"),
                              # occupancy is compared at its capture time, so waiting costs nothing here
                              tracker_args=("--max-wait-ms", "1500"))
        truth = TruthLog(group)
        yield base, truth, group
        truth.close()
    finally:
        group.stop()


def test_the_detector_path_runs_and_the_recorder_writes_history(live) -> None:
    base, _, group = live
    names: set[str] = set()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        names = {s["name"] for s in get_json(f"{base}/api/health")["services"]}
        if {"ingest", "detector", "projector", "tracker", "recorder", "gateway"} <= names:
            break
        time.sleep(0.5)
    assert {"ingest", "detector", "projector", "tracker", "recorder", "gateway"} <= names, group.log_dir
    assert (group.log_dir / "history.db").is_file()


def test_rest_occupancy_follows_the_ground_truth_with_the_detector_in_the_loop(live) -> None:
    base, truth, group = live
    time.sleep(8)  # models load, tracks need 3 detections to be confirmed
    errors, counted = [], []
    deadline = time.monotonic() + 30
    while len(errors) < 10 and time.monotonic() < deadline:
        occupancy = get_json(f"{base}/api/occupancy")
        expected = truth.count_at(occupancy["time_ns"])
        if expected is not None:
            errors.append(occupancy["total"] - expected)
            counted.append(expected)
        time.sleep(0.5)
    print("ground truth", counted, "errors", errors)
    assert len(errors) >= 5, f"too few occupancy samples matched a ground-truth frame; logs in {group.log_dir}"
    assert max(abs(e) for e in errors) <= 3, errors
    assert abs(sum(errors) / len(errors)) <= 1.5, errors
    assert max(counted) >= 3  # people were there to be counted
    cameras = {c["id"]: c for c in get_json(f"{base}/api/cameras")["items"]}
    assert all(cameras[c]["frames_received"] > 0 for c in SERVED), cameras


def test_garbage_frames_do_not_stop_the_detector(live) -> None:
    base, truth, group = live
    keys = bus.Keys(SITE_ID)
    camera = SPARE
    header = FrameHeader(camera=camera, seq=1, capture_ns=time.time_ns(), width=64, height=48)
    wrong_shape = FrameHeader(camera=camera, seq=2, capture_ns=time.time_ns(), width=100, height=20)
    bad_jpeg = FrameHeader(camera=camera, seq=3, capture_ns=time.time_ns(), width=64, height=64, encoding="jpeg")
    garbage = [
        (b"\x00" * 10, header.model_dump_json().encode()),  # too few bytes for its header
        (b"\x01" * (100 * 20 * 3), wrong_shape.model_dump_json().encode()),  # not the camera's aspect ratio
        (b"not a jpeg at all", bad_jpeg.model_dump_json().encode()),
        (np.zeros(64 * 48 * 3, np.uint8).tobytes(), None),  # no header
        (b"\x00\xff", b"{not json"),
    ]
    before = get_json(f"{base}/api/occupancy")["time_ns"]
    for _ in range(3):
        for payload, attachment in garbage:
            truth.session.put(keys.frame(camera), payload, attachment=attachment)
        time.sleep(0.3)
    time.sleep(3)
    assert not group.dead(), [c.name for c in group.dead()]
    after = get_json(f"{base}/api/occupancy")
    assert after["time_ns"] > before
    log = (group.log_dir / "detector.log").read_text()
    assert "rejected a message" in log
