from __future__ import annotations

import importlib.util
import threading

import cv2
import numpy as np
import pytest

from bevflow.detect.window import scaled_window
from bevflow.detections import Boxes
from bevflow.schemas import FrameHeader
from bevflow.sim.bodies import BodyShape
from bevflow.sim.render_feed import RenderedCameras
from bevflow.sim.scene import SceneConfig, SceneFrame
from bevflow.site import parse_site

from bevflow_services import bus
from bevflow_services.detector.main import BadFrame, FrameDetector, serve, share_cores
from bevflow_services.detector.schedule import ReadyCameras
from bevflow_services.runtime import UserError

SITE = parse_site("""
site: hall
cameras:
  - {id: a, image_size: [1000, 800], intrinsics: {fx: 300, fy: 300, cx: 499.5, cy: 399.5}, pose: {position: [0, 0, 4.0]}}
  - {id: b, image_size: [1000, 800], intrinsics: {fx: 300, fy: 300, cx: 499.5, cy: 399.5}, pose: {position: [6, 0, 4.0]}}
""")


class FakeDetector:
    """Stands in for ``Detector``: one box at fixed frame pixels; remembers its calls."""

    def __init__(self, box: tuple[float, float, float, float] = (10.0, 20.0, 30.0, 60.0)) -> None:
        self.box = box
        self.calls: list[tuple[tuple[int, ...], float, float]] = []

    def detect(self, image: np.ndarray, camera_height_m: float, focal_px: float) -> Boxes:
        self.calls.append((image.shape, camera_height_m, focal_px))
        return Boxes(xyxy=np.array([self.box]), confidence=np.array([0.8]))


def header(camera: str = "a", width: int = 1000, height: int = 800, encoding: str = "bgr8", seq: int = 5) -> FrameHeader:
    return FrameHeader(camera=camera, seq=seq, capture_ns=123_456, width=width, height=height, encoding=encoding)


@pytest.mark.parametrize("scale", [1.0, 0.5, 0.25])
def test_boxes_come_back_in_the_calibrated_pixels_whatever_the_frame_size(scale: float) -> None:
    fake = FakeDetector()
    w, h = int(1000 * scale), int(800 * scale)
    message = FrameDetector(SITE, {"a": fake}).detect(header(width=w, height=h), np.zeros((h, w, 3), np.uint8))
    assert (message.camera, message.seq, message.capture_ns) == ("a", 5, 123_456)
    expected = (np.array([10.0, 20.0, 30.0, 60.0]) + 0.5) / scale - 0.5
    np.testing.assert_allclose(message.boxes[0], expected)
    assert message.confidence == [pytest.approx(0.8)]
    # The detector is told the frame's own focal length, so it scales it the right amount.
    assert fake.calls == [((h, w, 3), pytest.approx(4.0), pytest.approx(300 * scale))]


WINDOWED = parse_site("""
site: hall
cameras:
  - {id: a, image_size: [1000, 800], intrinsics: {fx: 300, fy: 300, cx: 499.5, cy: 399.5}, pose: {position: [0, 0, 4.0]},
     monitored_radius_m: 3.0}
""")


@pytest.mark.parametrize(("scale", "whole_frame"), [(1.0, False), (0.5, False), (0.5, True)])
def test_only_the_window_around_the_monitored_radius_is_searched(scale: float, whole_frame: bool) -> None:
    fake = FakeDetector()
    w, h = int(1000 * scale), int(800 * scale)
    worker = FrameDetector(WINDOWED, {"a": fake}, whole_frame=whole_frame)
    message = worker.detect(header(width=w, height=h), np.zeros((h, w, 3), np.uint8))
    x0, y0, x1, y1 = scaled_window(None if whole_frame else worker.windows["a"], scale, w, h)
    assert fake.calls == [((y1 - y0, x1 - x0, 3), pytest.approx(4.0), pytest.approx(300 * scale))]
    assert whole_frame or (x1 - x0) * (y1 - y0) < 0.8 * w * h
    # the box found in the window comes back in the calibrated pixels of the whole image
    expected = (np.array([10.0, 20.0, 30.0, 60.0]) + [x0, y0, x0, y0] + 0.5) / scale - 0.5
    np.testing.assert_allclose(message.boxes[0], expected)


def test_jpeg_and_grey_frames_are_detected_in_colour() -> None:
    fake = FakeDetector()
    worker = FrameDetector(SITE, {"a": fake})
    image = np.full((400, 500, 3), 90, np.uint8)
    ok, jpeg = cv2.imencode(".jpg", image)
    assert ok
    worker.detect(header(width=500, height=400, encoding="jpeg"), jpeg.ravel())
    worker.detect(header(width=500, height=400, encoding="gray8"), np.zeros((400, 500), np.uint8))
    assert [c[0] for c in fake.calls] == [(400, 500, 3), (400, 500, 3)]


@pytest.mark.parametrize(
    ("frame_header", "image", "reason"),
    [
        (header(camera="zz"), np.zeros((800, 1000, 3), np.uint8), "unknown_camera"),
        (header(width=1000, height=500), np.zeros((500, 1000, 3), np.uint8), "frame_size"),
        (header(width=64, height=64, encoding="jpeg"), np.frombuffer(b"not a jpeg", np.uint8), "undecodable"),
        (header(width=500, height=400, encoding="jpeg"), cv2.imencode(".jpg", np.zeros((40, 50, 3), np.uint8))[1].ravel(),
         "frame_size"),
    ],
)
def test_frames_that_do_not_fit_their_camera_are_refused(frame_header: FrameHeader, image: np.ndarray, reason: str) -> None:
    fake = FakeDetector()
    with pytest.raises(BadFrame) as raised:
        FrameDetector(SITE, {"a": fake}).detect(frame_header, image)
    assert raised.value.reason == reason
    assert fake.calls == []


class FakeInbox:
    def __init__(self, key: str, frames: list[bus.Frame]) -> None:
        self.key = key
        self.frames = frames

    def take(self, timeout: float | None = None) -> bus.Frame | None:
        return self.frames.pop(0) if self.frames else None


class FakePublication:
    def __init__(self) -> None:
        self.sent: list = []

    def put(self, message) -> None:  # noqa: ANN001
        self.sent.append(message)


class ExplodingDetector(FakeDetector):
    def detect(self, image: np.ndarray, camera_height_m: float, focal_px: float) -> Boxes:
        raise RuntimeError("a bug")


@pytest.mark.parametrize("workers", [1, 2])
def test_the_loop_skips_bad_frames_and_bugs_and_goes_on_with_the_other_cameras(workers: int) -> None:
    frame = np.zeros((400, 500, 3), np.uint8)
    inboxes = {
        "a": FakeInbox("k/a", [bus.Frame(header("a", 500, 400, seq=1), frame), bus.Frame(header("b", 500, 400, seq=2), frame),
                               bus.Frame(header("a", 500, 100, seq=3), np.zeros((100, 500, 3), np.uint8)),
                               bus.Frame(header("a", 500, 400, seq=4), frame)]),
        "b": FakeInbox("k/b", [bus.Frame(header("b", 500, 400, seq=9), frame)]),
    }
    publications = {"a": FakePublication(), "b": FakePublication()}
    stats, stop, ready = bus.BusStats(), threading.Event(), ReadyCameras()
    worker = FrameDetector(SITE, {"a": FakeDetector(), "b": ExplodingDetector()})
    thread = threading.Thread(target=serve, args=(inboxes, publications, worker, stats, stop, ready), kwargs={"workers": workers})
    thread.start()
    for _ in range(500):
        for camera, inbox in inboxes.items():
            if inbox.frames:
                ready.arrived(camera)
        if not any(i.frames for i in inboxes.values()):
            break
        threading.Event().wait(0.01)
    stop.set()
    thread.join(5)
    assert not thread.is_alive()
    assert [m.seq for m in publications["a"].sent] == [1, 4]
    assert publications["b"].sent == []
    assert stats.rejected == {"wrong_camera": 1, "frame_size": 1}
    assert stats.handler_errors == 1


class MeetingDetector(FakeDetector):
    """Returns only once ``parties`` calls are in the detector at the same time (or fails)."""

    def __init__(self, meeting: threading.Barrier) -> None:
        super().__init__()
        self.meeting = meeting

    def detect(self, image: np.ndarray, camera_height_m: float, focal_px: float) -> Boxes:
        self.meeting.wait(timeout=10)  # BrokenBarrierError if the frames came one at a time
        return super().detect(image, camera_height_m, focal_px)


def test_workers_detect_two_cameras_frames_at_the_same_time() -> None:
    frame = np.zeros((400, 500, 3), np.uint8)
    meeting = threading.Barrier(2)
    inboxes = {c: FakeInbox(f"k/{c}", [bus.Frame(header(c, 500, 400, seq=7), frame)]) for c in ("a", "b")}
    publications = {"a": FakePublication(), "b": FakePublication()}
    stats, stop, ready = bus.BusStats(), threading.Event(), ReadyCameras()
    for camera in inboxes:
        ready.arrived(camera)
    worker = FrameDetector(SITE, {"a": MeetingDetector(meeting), "b": MeetingDetector(meeting)})
    thread = threading.Thread(target=serve, args=(inboxes, publications, worker, stats, stop, ready), kwargs={"workers": 2})
    thread.start()
    for _ in range(500):
        if all(p.sent for p in publications.values()):
            break
        threading.Event().wait(0.01)
    stop.set()
    thread.join(5)
    assert not thread.is_alive()
    assert [m.seq for m in publications["a"].sent + publications["b"].sent] == [7, 7]
    assert stats.handler_errors == 0  # a broken meeting would have been counted as a bug


@pytest.mark.parametrize(
    ("cameras", "workers", "threads", "cores", "expected"),
    [
        (6, None, None, 2, (2, 1)),  # a worker per core, one thread each
        (1, None, None, 2, (1, 2)),  # one camera: its frames come one at a time, on both cores
        (3, None, None, 8, (3, 2)),  # no more workers than cameras; the cores shared among them
        (20, None, None, 8, (8, 1)),
        (6, 1, None, 2, (1, 2)),  # the old way: one frame at a time on every core
        (6, None, 4, 2, (2, 4)),  # as asked, even beyond the cores
        (6, 3, 1, 2, (3, 1)),
    ],
)
def test_the_cores_are_shared_among_the_workers(cameras: int, workers: int | None, threads: int | None, cores: int,
                                                expected: tuple[int, int]) -> None:  # fmt: skip
    assert share_cores(cameras, workers, threads, cores) == expected


@pytest.mark.parametrize(("workers", "threads", "named"), [(0, None, "--workers"), (None, 0, "--threads")])
def test_no_workers_or_threads_is_refused(workers: int | None, threads: int | None, named: str) -> None:
    with pytest.raises(UserError, match=named):
        share_cores(4, workers, threads, 2)


@pytest.mark.skipif(importlib.util.find_spec("onnxruntime") is None, reason="onnxruntime is not installed")
def test_the_shipped_model_finds_a_rendered_person_where_the_camera_sees_them() -> None:
    from bevflow.detect.runtime import Detector

    site = parse_site("""
site: one
cameras:
  - {id: c, image_size: [1280, 1280], intrinsics: {fx: 400, fy: 400, cx: 639.5, cy: 639.5}, pose: {position: [0, 0, 3.5]}}
""")
    feet = [(1.0, 0.5), (-1.2, -1.0)]
    n = len(feet)
    frame = SceneFrame(index=3, time_s=0.3, person_ids=np.arange(1, n + 1), identity=np.arange(n), group=np.full(n, -1),
                       feet_xy=np.array(feet), heading=np.zeros(n), gait_phase=np.zeros(n), speed=np.zeros(n),
                       posture=np.zeros(n, dtype=np.int64), body=BodyShape.standard(n))  # fmt: skip
    cams = RenderedCameras(site, SceneConfig(floor=(-5.0, -5.0, 5.0, 5.0), people=0, frames=1))
    image = cams.render("c", frame).image
    h, w = image.shape[:2]
    message = FrameDetector(site, {"c": Detector(threads=1)}).detect(header("c", w, h, seq=3), image)
    boxes = np.array(message.boxes)
    assert len(boxes) == n
    for x, y in feet:
        head = site.camera("c").project(np.array([[x, y, 1.6]]))[0]
        near_x = (boxes[:, 0] - 5 <= head[0]) & (head[0] <= boxes[:, 2] + 5)
        inside = near_x & (boxes[:, 1] - 5 <= head[1]) & (head[1] <= boxes[:, 3] + 5)
        assert inside.any(), (head, boxes)


class FakeRotatingDetector(FakeDetector):
    """Stands in for the rim-tile detector: also takes the centre people lie radially about."""

    def detect(self, image: np.ndarray, camera_height_m: float, focal_px: float, centre: tuple[float, float]) -> Boxes:  # type: ignore[override]
        self.centre = centre
        return super().detect(image, camera_height_m, focal_px)

    def detect_rotated(self) -> None: ...


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_a_rotation_aware_detector_is_told_where_the_nadir_is_in_its_window(scale: float) -> None:
    fake = FakeRotatingDetector()
    w, h = int(1000 * scale), int(800 * scale)
    worker = FrameDetector(WINDOWED, {"a": fake})
    worker.detect(header(width=w, height=h), np.zeros((h, w, 3), np.uint8))
    x0, y0, _, _ = scaled_window(worker.windows["a"], scale, w, h)
    # A camera looking straight down: its nadir is the principal point (499.5, 399.5).
    assert fake.centre == pytest.approx(((499.5 + 0.5) * scale - 0.5 - x0, (399.5 + 0.5) * scale - 0.5 - y0), abs=1e-6)


def _walker_frame(x: int) -> np.ndarray:
    """A grey floor with a dark person, 30 x 60 px, at column ``x``."""
    image = np.full((800, 1000, 3), 110, np.uint8)
    image[370:430, x : x + 30] = 25
    return image


# (person's column in each frame, ms after the previous frame) → which frames ran the detector.
@pytest.mark.parametrize(
    ("steps", "detected"),
    [([(480, 0), (480, 100), (480, 100), (480, 100)], [True, False, False, False]),  # standing still
     ([(480, 0), (500, 100), (520, 100), (540, 100)], [True, True, True, True]),  # walking
     ([(480, 0), (480, 600), (480, 600), (480, 100)], [True, False, True, False]),  # still, but a second old
     ([(480, 0), (480, 100), (530, 100), (530, 100)], [True, False, True, False])],  # stands, steps, stands
)
def test_with_skip_still_a_camera_whose_picture_is_unchanged_reuses_its_last_boxes(
        steps: list[tuple[int, int]], detected: list[bool]) -> None:  # fmt: skip
    from bevflow.detect.still import StillFrames

    fake = FakeDetector()
    worker = FrameDetector(SITE, {"a": fake}, whole_frame=True, still=StillFrames())
    t, ran, messages = 0, [], []
    for seq, (x, after_ms) in enumerate(steps):
        t += after_ms * 1_000_000
        calls = len(fake.calls)
        frame_header = FrameHeader(camera="a", seq=seq, capture_ns=t, width=1000, height=800)
        messages.append(worker.detect(frame_header, _walker_frame(x)))
        ran.append(len(fake.calls) > calls)
    assert ran == detected
    assert [(m.seq, m.capture_ns) for m in messages] == [(k, sum(s[1] for s in steps[: k + 1]) * 1_000_000) for k in range(len(steps))]
    assert all(m.model_dump(exclude={"seq", "capture_ns"}) == messages[0].model_dump(exclude={"seq", "capture_ns"}) for m in messages)
    assert sum(worker.reused.values()) == detected.count(False)


def test_without_skip_still_every_frame_is_detected() -> None:
    fake = FakeDetector()
    worker = FrameDetector(SITE, {"a": fake}, whole_frame=True)
    for seq in range(3):
        worker.detect(FrameHeader(camera="a", seq=seq, capture_ns=seq * 100_000_000, width=1000, height=800), _walker_frame(480))
    assert len(fake.calls) == 3 and not worker.reused


class FailingPublication(FakePublication):
    def put(self, message) -> None:  # noqa: ANN001
        raise RuntimeError("the session is gone")


def test_a_worker_that_fails_outside_a_frame_stops_the_service_with_its_error() -> None:
    frame = np.zeros((400, 500, 3), np.uint8)
    inboxes = {"a": FakeInbox("k/a", [bus.Frame(header("a", 500, 400, seq=1), frame)])}
    stats, stop, ready = bus.BusStats(), threading.Event(), ReadyCameras()
    ready.arrived("a")
    with pytest.raises(RuntimeError, match="the session is gone"):
        serve(inboxes, {"a": FailingPublication()}, FrameDetector(SITE, {"a": FakeDetector()}), stats, stop, ready, workers=2)
    assert stop.is_set()
