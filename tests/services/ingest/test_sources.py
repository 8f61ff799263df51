from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow_services.ingest.sources import LatestFrameReader, SourceError, Timeouts, read_frames
from bevflow_services.launcher import free_port
from tests.services.ingest.rtsp_server import RtspCamera


def write_video(path: Path, frames: int, size=(64, 48), fps: float = 10.0) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    for i in range(frames):
        writer.write(np.full((size[1], size[0], 3), i * 10, np.uint8))
    writer.release()


def wait_until(condition: Callable[[], bool], timeout_s: float) -> float | None:
    """Seconds until ``condition`` held, or None if it did not within ``timeout_s``."""
    started = time.monotonic()
    while time.monotonic() - started < timeout_s:
        if condition():
            return time.monotonic() - started
        time.sleep(0.02)
    return None


def test_a_video_file_is_read_to_its_end(tmp_path: Path) -> None:
    video = tmp_path / "cam.avi"
    write_video(video, 5, fps=50)
    got = []
    with pytest.raises(SourceError, match="stopped delivering"):
        for capture_ns, image in read_frames(str(video)):
            got.append((capture_ns, image))
    assert len(got) == 5 and got[0][1].shape == (48, 64, 3)
    assert np.allclose(np.diff([c for c, _ in got]), 20_000_000, atol=1_000_000)


def test_an_image_folder_is_read_in_name_order_skipping_unreadable_files(tmp_path: Path) -> None:
    for i in (2, 0, 1):
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), np.full((8, 8, 3), i, np.uint8))
    (tmp_path / "003.jpg").write_bytes(b"not an image")
    images = []
    before = time.time_ns()
    with pytest.raises(SourceError, match="no more images"):
        for capture_ns, image in read_frames(str(tmp_path), folder_fps=1000):
            images.append(int(image[0, 0, 0]))
            assert before <= capture_ns <= time.time_ns()
    assert images == [0, 1, 2]


@pytest.mark.parametrize(
    ("source", "message"),
    [("/no/such/camera.mp4", "cannot open camera source"), ("EMPTY_DIR", "holds no images")],
)
def test_broken_sources_say_which_source(tmp_path: Path, source: str, message: str) -> None:
    if source == "EMPTY_DIR":
        source = str(tmp_path)
    with pytest.raises(SourceError, match=message):
        next(read_frames(source))


def test_reader_keeps_only_the_newest_frame_and_retries_a_broken_source(tmp_path: Path) -> None:
    video = tmp_path / "cam.avi"
    write_video(video, 20, fps=100)
    reader = LatestFrameReader(str(video), backoff_s=(0.05, 0.1)).start()
    try:
        assert wait_until(lambda: reader.reconnects >= 2, 10) is not None
        frame = reader.take(timeout=1.0)
    finally:
        reader.stop()
    assert "stopped delivering" in reader.last_error
    assert frame is not None and frame.image.shape == (48, 64, 3)
    assert reader.frames_overwritten > 0  # nobody took frames while it read: only the newest was kept


def test_a_camera_that_cannot_be_opened_leaves_the_others_going(tmp_path: Path) -> None:
    video = tmp_path / "cam.avi"
    write_video(video, 20, fps=50)
    broken = LatestFrameReader(f"rtsp://admin:s3cret@127.0.0.1:{free_port()}/stream1", backoff_s=(0.05, 0.1)).start()
    working = LatestFrameReader(str(video)).start()
    try:
        assert wait_until(lambda: broken.reconnects >= 3 and working.frames_read >= 10, 5) is not None
        assert working.up and not broken.up
    finally:
        broken.stop()
        working.stop()
    assert broken.last_error.startswith("cannot open camera source 'rtsp://admin:***@127.0.0.1:")
    assert "s3cret" not in broken.last_error


@pytest.mark.parametrize(
    ("how", "stop_signal"),
    [("the camera process dies", signal.SIGKILL), ("the camera stalls with its connection open", signal.SIGSTOP)],
    ids=["killed", "stalled"],
)
def test_a_stream_that_stops_is_reported_down_and_read_again_when_it_comes_back(camera_servers, how, stop_signal) -> None:
    port = free_port()
    camera = camera_servers(port)
    # The shipped timeouts: a stall must show within the 5 s after which camera health calls a
    # camera down.
    reader = LatestFrameReader(f"tcp://127.0.0.1:{port}", backoff_s=(0.05, 0.2), timeouts=Timeouts()).start()
    try:
        assert wait_until(lambda: reader.up and reader.frames_read >= 10, 10) is not None, reader.last_error
        frame = reader.take(timeout=1.0)
        assert frame is not None and frame.image.shape == (120, 160, 3)
        assert abs(frame.capture_ns - time.time_ns()) < 1_000_000_000  # on this host's clock, not the stream's

        os.kill(camera.pid, stop_signal)
        down_after = wait_until(lambda: not reader.up, 5)
        assert down_after is not None, f"{how}: still up 5 s later"
        assert wait_until(lambda: reader.reconnects >= 1, 2) is not None
        print(f"{how}: down after {down_after:.2f} s ({reader.last_error})")

        read_before = reader.frames_read
        camera_servers(port)  # the camera comes back on the same address
        assert wait_until(lambda: reader.up and reader.frames_read >= read_before + 10, 10) is not None, reader.last_error
    finally:
        reader.stop()


def test_an_rtsp_camera_that_stalls_is_reported_down_and_read_again_when_it_comes_back(rtsp_camera: RtspCamera) -> None:
    reader = LatestFrameReader(rtsp_camera.url("admin:s3cret@"), backoff_s=(0.05, 0.2), timeouts=Timeouts()).start()
    try:
        assert wait_until(lambda: reader.up and reader.frames_read >= 10, 10) is not None, reader.last_error
        rtsp_camera.stall()
        down_after = wait_until(lambda: not reader.up, 5)
        assert down_after is not None, "still up 5 s after the camera stalled"
        print(f"RTSP camera stalled: down after {down_after:.2f} s")
        assert reader.last_error == f"camera source {rtsp_camera.url('admin:***@')!r} failed: nothing for 3 s"
        read_before = reader.frames_read
        rtsp_camera.resume()
        assert wait_until(lambda: reader.up and reader.frames_read >= read_before + 10, 10) is not None, reader.last_error
    finally:
        reader.stop()
    assert reader.reconnects >= 1
    assert all(t.startswith("RTP/AVP/TCP") for t in rtsp_camera.transports), rtsp_camera.transports
