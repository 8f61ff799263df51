"""Video files and streams through FFmpeg (PyAV): H.264 and H.265 decoded to BGR, played at their
own frame rate with the stream's timestamps; sources that cannot be opened or stall say so."""

from __future__ import annotations

import socket
import time
from contextlib import closing
from pathlib import Path

import av
import numpy as np
import pytest

from bevflow_services.ingest.errors import SourceError
from bevflow_services.ingest.video import Timeouts, ffmpeg_options, is_network_stream, video_frames
from bevflow_services.launcher import free_port
from tests.services.ingest.media import SIZE, colour_of, encoder_for, write_video
from tests.services.ingest.rtsp_server import RtspCamera

FRAMES, FPS = 10, 25


@pytest.mark.parametrize("codec", ["h264", "hevc", "mpeg4"])
def test_a_recorded_file_plays_in_real_time_with_its_own_timestamps(tmp_path: Path, codec: str) -> None:
    encoder = encoder_for(codec)
    if encoder is None:
        pytest.skip(f"this PyAV build has no {codec} encoder to make a test file with")
    path = tmp_path / f"camera-{codec}.mp4"
    write_video(path, encoder, FRAMES, FPS)
    with av.open(str(path)) as written:
        assert written.streams.video[0].codec_context.name == codec

    started = time.monotonic()
    frames = []
    with pytest.raises(SourceError, match="stopped delivering frames"):
        for capture_ns, image in video_frames(str(path)):
            frames.append((capture_ns, image))
    took = time.monotonic() - started

    assert len(frames) == FRAMES
    assert all(image.shape == (SIZE[1], SIZE[0], 3) and image.dtype == np.uint8 for _, image in frames)
    for index, (_, image) in enumerate(frames):  # BGR, not RGB: red stays in the last channel
        assert np.abs(image.mean(axis=(0, 1)) - colour_of(index)).max() < 12, (index, image.mean(axis=(0, 1)))
    gaps_ms = np.diff([capture for capture, _ in frames]) / 1e6
    assert np.allclose(gaps_ms, 1000 / FPS, atol=1.0), gaps_ms
    assert took >= 0.9 * (FRAMES - 1) / FPS  # played at its frame rate, not as fast as it decodes


def test_an_rtsp_camera_is_read_over_tcp_with_its_rtp_timestamps(rtsp_camera: RtspCamera) -> None:
    frames = []
    with closing(video_frames(rtsp_camera.url("admin:s3cret@"), Timeouts(open_s=5, read_s=2))) as stream:
        for capture_ns, image in stream:
            frames.append((capture_ns, time.time_ns(), image))
            if len(frames) == 45:
                break
    assert rtsp_camera.transports and all(t.startswith("RTP/AVP/TCP") for t in rtsp_camera.transports)
    assert all(image.shape == (SIZE[1], SIZE[0], 3) for _, _, image in frames)
    for index, (_, _, image) in enumerate(frames):  # every frame, in order, none lost
        assert np.abs(image.mean(axis=(0, 1)) - colour_of(index)).max() < 12, (index, image.mean(axis=(0, 1)))
    # The first second or so arrives at once (FFmpeg reads it to learn the stream); no frame is
    # stamped later than it arrived, and once live they keep the camera's 40 ms spacing.
    assert all(capture <= arrived for capture, arrived, _ in frames)
    gaps_ms = np.diff([capture for capture, _, _ in frames[-10:]]) / 1e6
    assert np.allclose(gaps_ms, 1000 / FPS, atol=1.0), gaps_ms


@pytest.mark.parametrize(
    ("source", "live", "options"),
    [
        ("rtsp://admin:pw@10.0.0.7/stream1", True, {"rtsp_transport": "tcp", "timeout": "3000000"}),
        ("RTSPS://10.0.0.7/stream1", True, {"rtsp_transport": "tcp", "timeout": "3000000"}),
        ("http://10.0.0.7/video.mjpg", True, {}),
        ("tcp://127.0.0.1:9000", True, {}),
        ("file:///recordings/cam.mp4", False, {}),
        ("/recordings/cam.mp4", False, {}),
    ],
)
def test_rtsp_goes_over_tcp_with_a_socket_timeout(source: str, live: bool, options: dict[str, str]) -> None:
    assert is_network_stream(source) == live
    assert ffmpeg_options(source, Timeouts(open_s=10, read_s=3)) == options


def _not_a_video(tmp_path: Path) -> str:
    path = tmp_path / "notes.mp4"
    path.write_text("not a video")
    return str(path)


def _sound_only(tmp_path: Path) -> str:
    path = tmp_path / "microphone.wav"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("pcm_s16le", rate=8000)
        frame = av.AudioFrame.from_ndarray(np.zeros((1, 800), np.int16), format="s16", layout="mono")
        frame.sample_rate = 8000
        container.mux(stream.encode(frame))
    return str(path)


@pytest.mark.parametrize(
    ("make_source", "shown"),
    [
        (lambda _: f"rtsp://admin:s3cret@127.0.0.1:{free_port()}/stream1", "'rtsp://admin:***@127.0.0.1:"),
        (lambda _: f"tcp://127.0.0.1:{free_port()}", "'tcp://127.0.0.1:"),
        (lambda _: "/no/such/camera.mp4", "'/no/such/camera.mp4': No such file or directory"),
        (_not_a_video, "notes.mp4': Invalid data"),
        (_sound_only, "microphone.wav': it has no video stream"),
    ],
    ids=["rtsp refused", "tcp refused", "missing file", "not a video", "sound only"],
)
def test_a_source_that_cannot_be_opened_is_named_with_its_password_masked(tmp_path: Path, make_source, shown: str) -> None:
    with pytest.raises(SourceError) as caught:
        next(video_frames(make_source(tmp_path), Timeouts(open_s=2, read_s=2)))
    message = str(caught.value)
    assert message.startswith("cannot open camera source") and shown in message, message
    assert "s3cret" not in message


def test_a_stream_that_connects_and_says_nothing_times_out() -> None:
    with socket.create_server(("127.0.0.1", 0)) as silent:  # accepts (the kernel does), never sends
        source = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        started = time.monotonic()
        with pytest.raises(SourceError, match="nothing for 0.5 s"):
            next(video_frames(source, Timeouts(open_s=0.5, read_s=0.5)))
    assert time.monotonic() - started < 3
