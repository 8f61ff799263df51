"""Stand-in cameras for the ingest's tests."""

from __future__ import annotations

import subprocess
from collections.abc import Callable, Iterator

import pytest

from tests.services.ingest import mpegts_server
from tests.services.ingest.media import encoder_for
from tests.services.ingest.rtsp_server import RtspCamera


@pytest.fixture
def rtsp_camera() -> Iterator[RtspCamera]:
    if encoder_for("h264") is None:
        pytest.skip("this PyAV build has no H.264 encoder to serve an RTSP camera with")
    camera = RtspCamera()
    yield camera
    camera.close()


@pytest.fixture
def camera_servers() -> Iterator[Callable[[int], subprocess.Popen[bytes]]]:
    """Starts MPEG-TS cameras in processes of their own (``mpegts_server``); kills those still
    running at the end."""
    started: list[subprocess.Popen[bytes]] = []

    def start(port: int) -> subprocess.Popen[bytes]:
        started.append(mpegts_server.start(port))
        return started[-1]

    yield start
    for process in started:
        process.kill()  # a stopped (SIGSTOP) process dies of SIGKILL too
        process.wait(5)
