"""A real camera stream through ``bevflow serve ingest``: read through FFmpeg, lost and found again,
and reported in camera health (the tracker's camera_down / camera_up, the gateway's /api/cameras).

The camera is a stand-in served over TCP by another process (``mpegts_server``), H.264 in
MPEG-TS in real time. The ingest, tracker and gateway run as real processes; the test itself plays
a detector and projector that see nobody, so the tracker and gateway hear from a camera exactly
while its frames flow (no model is loaded). A second camera's source cannot be opened: the first
must not notice, and its password must stay out of the ingest's log.
"""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from bevflow.schemas import CameraCylinders, CameraHealthEvent, Detections2D, Event

from bevflow_services import bus
from bevflow_services.launcher import ServiceGroup, free_port
from tests.e2e.http import get_json
from tests.services.ingest import mpegts_server

pytestmark = [pytest.mark.e2e, pytest.mark.slow]
SITE_ID = "stream-e2e"
CAMERA = """  - id: {id}
    source: {source}
    image_size: [160, 120]
    intrinsics: {{fx: 50, fy: 50, cx: 79.5, cy: 59.5}}
    pose: {{position: [{x}, 0, 3.5]}}
"""


def site_file(folder: Path, stream_port: int) -> Path:
    cameras = (CAMERA.format(id="a", source=f"tcp://127.0.0.1:{stream_port}", x=0)
               + CAMERA.format(id="b", source=f"rtsp://admin:s3cret@127.0.0.1:{free_port()}/stream1", x=6))
    path = folder / "site.yaml"
    path.write_text(f"site: {SITE_ID}\nfloor: [-4, -4, 10, 4]\ncameras:\n{cameras}")
    return path


class BlindDetector:
    """For each frame on the bus, empty detections and cylinders of the same camera, sequence
    number and capture time; and the camera health events the tracker publishes."""

    def __init__(self, group: ServiceGroup) -> None:
        cfg = bus.BusConfig(mode="peer", listen=("tcp/127.0.0.1:0",), connect=(f"tcp/127.0.0.1:{group.hub_port}",))
        self.session = bus.open_session(cfg)
        keys = bus.Keys(SITE_ID)
        self.lock = threading.Lock()
        self.frames: dict[str, int] = {}
        self.health: list[CameraHealthEvent] = []
        self.outputs = {
            camera: (bus.Publication(self.session, keys.detections(camera), bus.JsonCodec(Detections2D)),
                     bus.Publication(self.session, keys.cylinders(camera), bus.JsonCodec(CameraCylinders)))
            for camera in ("a", "b")}
        self.subscriptions = [bus.subscribe(self.session, keys.frame("*"), bus.FRAMES, self._on_frame),
                              bus.subscribe(self.session, keys.events, bus.JsonCodec[Event](Event, "Event"), self._on_event)]

    def _on_frame(self, frame: bus.Frame) -> None:
        h = frame.header
        detections, cylinders = self.outputs[h.camera]
        detections.put(Detections2D(camera=h.camera, seq=h.seq, capture_ns=h.capture_ns))
        cylinders.put(CameraCylinders(camera=h.camera, seq=h.seq, capture_ns=h.capture_ns))
        with self.lock:
            self.frames[h.camera] = self.frames.get(h.camera, 0) + 1

    def _on_event(self, event: Event) -> None:
        if isinstance(event, CameraHealthEvent):
            with self.lock:
                self.health.append(event)

    def frames_of(self, camera: str) -> int:
        with self.lock:
            return self.frames.get(camera, 0)

    def health_of(self, camera: str) -> list[str]:
        """The camera's camera_down (still open) and camera_up events so far, in order."""
        with self.lock:
            return [e.type for e in self.health if e.camera == camera and (e.type == "camera_up" or e.end_ns is None)]

    def close(self) -> None:
        for subscription in self.subscriptions:
            subscription.close()
        for outputs in self.outputs.values():
            for publication in outputs:
                publication.close()
        self.session.close()


def wait_until(condition: Callable[[], bool], timeout_s: float, what: str, group: ServiceGroup) -> float:
    started = time.monotonic()
    while time.monotonic() - started < timeout_s:
        if condition():
            return time.monotonic() - started
        assert not group.dead(), f"{[c.name for c in group.dead()]} died; logs in {group.log_dir}"
        time.sleep(0.05)
    raise AssertionError(f"{what}: not within {timeout_s:g} s; logs in {group.log_dir}")


def test_a_stream_lost_and_found_is_reported_in_camera_health(tmp_path: Path) -> None:
    stream_port, http_port = free_port(), free_port()
    servers: list[subprocess.Popen[bytes]] = [mpegts_server.start(stream_port, seconds=120)]
    group = ServiceGroup(site=str(site_file(tmp_path, stream_port)), log_dir=tmp_path / "logs")
    detector = None
    try:
        # b never streams: reported down once it has had --camera-first-report to send a first result.
        group.start("tracker", "--camera-up-after", "1", "--camera-first-report", "5")
        group.start("gateway", "--port", str(http_port), "--auth", "off", "--no-view3d")
        base = f"http://127.0.0.1:{http_port}"
        group.wait_http(f"{base}/api/health")
        detector = BlindDetector(group)
        group.start("ingest")

        def state(camera: str) -> str:
            return get_json(f"{base}/api/cameras/{camera}")["state"]

        wait_until(lambda: detector.frames_of("a") >= 25 and state("a") == "up", 30, "camera a's frames", group)
        wait_until(lambda: detector.health_of("b") == ["camera_down"], 15, "camera b reported down", group)
        assert detector.health_of("a") == [] and state("b") == "down"

        servers[0].kill()  # the camera goes away
        down_after = wait_until(lambda: state("a") == "down", 10, "camera a down at the gateway", group)
        wait_until(lambda: detector.health_of("a") == ["camera_down"], 3, "the tracker's camera_down for a", group)

        servers.append(mpegts_server.start(stream_port, seconds=120))  # and comes back
        up_after = wait_until(lambda: detector.health_of("a") == ["camera_down", "camera_up"] and state("a") == "up",
                              30, "camera a up again", group)
        print(f"camera a: down at the gateway {down_after:.1f} s after its stream died, up again {up_after:.1f} s "
              "after it came back (the ingest's backoff, then --camera-up-after 1)")
        assert not group.dead()
        log = (group.log_dir / "ingest.log").read_text()
        assert "rtsp://admin:***@127.0.0.1" in log and "s3cret" not in log
    finally:
        if detector is not None:
            detector.close()
        group.stop()
        for server in servers:
            server.kill()
            server.wait(5)
