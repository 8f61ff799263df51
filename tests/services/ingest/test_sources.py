from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow_services.ingest.sources import LatestFrameReader, SourceError, read_frames


def write_video(path: Path, frames: int, size=(64, 48)) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, size)
    for i in range(frames):
        writer.write(np.full((size[1], size[0], 3), i * 10, np.uint8))
    writer.release()


def test_a_video_file_is_read_to_its_end(tmp_path: Path) -> None:
    video = tmp_path / "cam.avi"
    write_video(video, 5)
    got = []
    with pytest.raises(SourceError, match="stopped delivering"):
        for image in read_frames(str(video)):
            got.append(image)
    assert len(got) == 5 and got[0].shape == (48, 64, 3)


def test_an_image_folder_is_read_in_name_order_skipping_unreadable_files(tmp_path: Path) -> None:
    for i in (2, 0, 1):
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), np.full((8, 8, 3), i, np.uint8))
    (tmp_path / "003.jpg").write_bytes(b"not an image")
    images = []
    with pytest.raises(SourceError, match="no more images"):
        for image in read_frames(str(tmp_path), folder_fps=1000):
            images.append(int(image[0, 0, 0]))
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
    write_video(video, 20)
    reader = LatestFrameReader(str(video), backoff_s=(0.05, 0.1)).start()
    try:
        deadline = time.monotonic() + 10
        while reader.reconnects < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        frame = reader.take(timeout=1.0)
    finally:
        reader.stop()
    assert reader.reconnects >= 2 and "stopped delivering" in reader.last_error
    assert frame is not None and frame.image.shape == (48, 64, 3)
    assert reader.frames_overwritten > 0  # nobody took frames while it read: only the newest was kept
