"""Camera streams and video files read through FFmpeg (PyAV), decoded to BGR frames.

RTSP goes over TCP: over UDP a lost packet tears a frame, and fisheye frames are large. Opening
and reading are bounded (``Timeouts``): a camera that does not answer, or a stream that stops
delivering without closing, raises ``SourceError`` instead of hanging, so the reader reconnects
and camera health sees the camera go quiet. Each frame carries its capture time from the
stream's own timestamps (``stream_clock``); a video file plays at its own frame rate, as a camera
would deliver it. Any codec FFmpeg decodes is read; cameras send H.264 or H.265.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction

import av
import av.error
import numpy as np

from bevflow.units import NS_PER_S

from bevflow_services.ingest.errors import SourceError
from bevflow_services.ingest.stream_clock import StreamClock
from bevflow_services.redact import redact

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Timeouts:
    """Seconds to wait for a stream to open (connect, handshake, first frames to probe) and for
    each read once open; a stall longer than ``read_s`` counts as a broken stream."""

    open_s: float = 10.0
    read_s: float = 3.0


DEFAULT_TIMEOUTS = Timeouts()


def is_network_stream(source: str) -> bool:
    """An URL other than ``file:`` (RTSP, HTTP, TCP ...): a live stream, not a file."""
    scheme, sep, _ = source.partition("://")
    return bool(sep) and scheme.lower() != "file"


def ffmpeg_options(source: str, timeouts: Timeouts) -> dict[str, str]:
    """FFmpeg's options for opening ``source``."""
    if source.lower().startswith(("rtsp://", "rtsps://")):
        # FFmpeg's own socket timeout (microseconds) as well as PyAV's interrupt: it also bounds
        # the RTSP handshake's TCP reads.
        return {"rtsp_transport": "tcp", "timeout": str(int(timeouts.read_s * 1e6))}
    return {}


def video_frames(source: str, timeouts: Timeouts = DEFAULT_TIMEOUTS) -> Iterator[tuple[int, np.ndarray]]:
    """(capture time ns, BGR image) for each frame of a stream or video file, until it ends or
    breaks (``SourceError``, naming the source with its password masked)."""
    shown = redact(source)
    live = is_network_stream(source)
    try:
        container = av.open(source, options=ffmpeg_options(source, timeouts),
                            timeout=(timeouts.open_s, timeouts.read_s))
    except av.error.FFmpegError as exc:
        raise SourceError(f"cannot open camera source {shown!r}: {_reason(exc, timeouts.open_s)}") from None
    with container:
        if not container.streams.video:
            raise SourceError(f"cannot open camera source {shown!r}: it has no video stream")
        stream = container.streams.video[0]
        clock = StreamClock(shown, follow_arrivals=live)
        try:
            for frame in _decoded(container, stream, shown, timeouts.read_s):
                capture_ns = clock.stamp(_pts_ns(frame), time.time_ns())
                if not live:  # a file: show each frame when its time comes
                    time.sleep(max(0.0, (capture_ns - time.time_ns()) / NS_PER_S))
                yield capture_ns, frame.to_ndarray(format="bgr24")
        except av.error.FFmpegError as exc:
            raise SourceError(f"camera source {shown!r} failed: {_reason(exc, timeouts.read_s)}") from None
    raise SourceError(f"camera source {shown!r} stopped delivering frames")


def _decoded(container: av.container.InputContainer, stream: av.VideoStream, shown: str,
             read_s: float) -> Iterator[av.VideoFrame]:
    """The stream's frames; a packet that does not decode (a torn frame on a flaky link) is
    skipped, not a reason to drop the connection."""
    packets = container.demux(stream)
    skipped = 0
    while True:
        asked = time.monotonic()
        packet = next(packets, None)
        if packet is None:
            return
        if time.monotonic() - asked >= read_s:
            # A read that outlasted the timeout was interrupted: FFmpeg hands over the frame it
            # held back before it reports the error on the next read (one more timeout).
            raise SourceError(f"camera source {shown!r} failed: nothing for {read_s:g} s")
        try:
            yield from packet.decode()
        except av.error.InvalidDataError:
            skipped += 1
            if skipped == 1:
                log.warning("camera source %s: skipping packets that do not decode", shown)


def _pts_ns(frame: av.VideoFrame) -> int | None:
    if frame.pts is None or frame.time_base is None:
        return None
    tb = Fraction(frame.time_base)
    return frame.pts * tb.numerator * NS_PER_S // tb.denominator


def _reason(exc: av.error.FFmpegError, waited_s: float) -> str:
    """What went wrong, without the URL FFmpeg's message repeats (it may hold a password)."""
    if isinstance(exc, av.error.ExitError):  # PyAV's timeout interrupted FFmpeg
        return f"nothing for {waited_s:g} s"
    return exc.strerror or type(exc).__name__
