"""A camera stand-in: H.264 in MPEG-TS, served over TCP in real time to the first client.

    python -m tests.services.ingest.mpegts_server --port 18554 [--fps 25] [--seconds 60]

It stops when the client goes away or after ``--seconds`` (so a test that dies leaves none behind).
``start`` runs it as a separate process, which a test kills (the camera is gone) or stops with
SIGSTOP (the camera stalls, its connection open and silent).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import av
import av.error

from tests.services.ingest.media import add_video, encode, encoder_for, picture

ROOT = Path(__file__).resolve().parents[3]


def start(port: int, seconds: float = 30.0) -> subprocess.Popen[bytes]:
    """The server on ``port``, in a process of its own; it listens within about a second."""
    argv = [sys.executable, "-m", "tests.services.ingest.mpegts_server", "--port", str(port), "--seconds", str(seconds)]
    return subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def serve(port: int, fps: int, seconds: float) -> None:
    encoder = encoder_for("h264") or "mpeg4"
    # listen=1 waits here for one client; flush_packets sends each frame at once, as a camera does.
    with av.open(f"tcp://127.0.0.1:{port}?listen=1", "w", format="mpegts", options={"flush_packets": "1"}) as out:
        stream = add_video(out, encoder, fps)
        began = time.monotonic()
        for index in range(int(seconds * fps)):
            encode(out, stream, picture(index), index)
            time.sleep(max(0.0, began + (index + 1) / fps - time.monotonic()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--fps", type=int, default=25)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    try:
        serve(args.port, args.fps, args.seconds)
    except (av.error.FFmpegError, OSError):  # the client hung up: a camera would go on, this one is done
        pass


if __name__ == "__main__":
    main()
