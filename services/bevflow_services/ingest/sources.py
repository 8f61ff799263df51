"""Camera sources: RTSP/HTTP streams, video files and image folders, read into BGR frames.

A source is read on its own thread and only its newest frame is kept, so a slow consumer gets
the latest picture, never a backlog. A stream that fails, or stalls for longer than its read
timeout, is reopened with exponential backoff (1 s doubling up to 30 s) and its state (``up``,
``reconnects``, ``last_error``) is visible for health reporting. Streams and video files are read
through FFmpeg (``video``) and stamped from their own timestamps; an image folder's pictures are
stamped when read (integer ns).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bevflow_services.ingest.errors import SourceError
from bevflow_services.ingest.video import DEFAULT_TIMEOUTS, Timeouts, video_frames
from bevflow_services.redact import redact

__all__ = ["CapturedFrame", "LatestFrameReader", "SourceError", "Timeouts", "read_frames"]

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff"}


@dataclass(frozen=True)
class CapturedFrame:
    seq: int
    capture_ns: int
    image: np.ndarray  # H x W x 3 uint8, BGR


def read_frames(source: str, folder_fps: float = 10.0,
                timeouts: Timeouts = DEFAULT_TIMEOUTS) -> Iterator[tuple[int, np.ndarray]]:
    """(capture time ns, BGR image) for each frame of one source until it ends or breaks
    (``SourceError``)."""
    path = Path(source)
    if path.is_dir():
        yield from _folder_frames(path, folder_fps)
        return
    yield from video_frames(source, timeouts)


def _folder_frames(folder: Path, fps: float) -> Iterator[tuple[int, np.ndarray]]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise SourceError(f"image folder {folder} holds no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
    for file in files:
        started = time.monotonic()
        image = cv2.imread(str(file), cv2.IMREAD_COLOR)
        if image is None:
            log.warning("skipping %s: not a readable image", file)
            continue
        yield time.time_ns(), image
        time.sleep(max(0.0, 1.0 / fps - (time.monotonic() - started)))
    raise SourceError(f"image folder {folder} has no more images")


class LatestFrameReader:
    """Reads a source on a daemon thread, reconnecting with backoff; ``latest`` is the newest
    frame not yet taken. ``loop=False`` stops at the end of a file or folder instead."""

    def __init__(self, source: str, folder_fps: float = 10.0, loop: bool = True,
                 backoff_s: tuple[float, float] = (1.0, 30.0), timeouts: Timeouts = DEFAULT_TIMEOUTS) -> None:
        self.source = source
        self.folder_fps = folder_fps
        self.timeouts = timeouts
        self.loop = loop
        self.backoff_s = backoff_s
        self.up = False
        self.reconnects = 0
        self.frames_read = 0
        self.frames_overwritten = 0
        self.last_error = ""
        self._latest: CapturedFrame | None = None
        self._ready = threading.Condition()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"source {redact(source)}", daemon=True)

    def start(self) -> LatestFrameReader:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        with self._ready:
            self._ready.notify_all()

    def take(self, timeout: float) -> CapturedFrame | None:
        with self._ready:
            if self._latest is None:
                self._ready.wait(timeout)
            frame, self._latest = self._latest, None
        return frame

    def _run(self) -> None:
        delay = self.backoff_s[0]
        while not self._stop.is_set():
            try:
                for capture_ns, image in read_frames(self.source, self.folder_fps, self.timeouts):
                    self._publish(capture_ns, image)
                    delay = self.backoff_s[0]
                    if self._stop.is_set():
                        return
            except SourceError as exc:
                self.last_error = str(exc)
            except cv2.error as exc:
                self.last_error = redact(f"camera source {self.source!r}: {exc}")
            except Exception as exc:  # a reader outlives whatever its source does; the others never notice
                log.exception("reading camera source %s", redact(self.source))
                self.last_error = redact(f"camera source {self.source!r}: {type(exc).__name__}: {exc}")
            self.up = False
            if not self.loop:
                return
            log.warning("%s; retrying in %g s", self.last_error, delay)
            self.reconnects += 1
            self._stop.wait(delay)
            delay = min(delay * 2, self.backoff_s[1])

    def _publish(self, capture_ns: int, image: np.ndarray) -> None:
        with self._ready:
            if self._latest is not None:
                self.frames_overwritten += 1
            if not self.up and self.reconnects:
                log.info("camera source %s delivers frames again", redact(self.source))
            self._latest = CapturedFrame(self.frames_read, capture_ns, image)
            self.frames_read += 1
            self.up = True
            self._ready.notify_all()
