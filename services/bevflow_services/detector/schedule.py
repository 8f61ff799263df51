"""Which camera's frame a detector worker takes next.

Each camera keeps only its newest frame (latest frame wins); ``ReadyCameras`` knows which
cameras have one waiting and hands them to the workers, the camera that has waited longest
first, each camera to one worker at a time so that its boxes go out in the order of its frames.
A worker that finishes takes the next waiting camera at once: no frame waits for other cameras'
frames to be done, as it would if the workers went through the cameras in passes.
"""

from __future__ import annotations

import threading
import time


class ReadyCameras:
    """The cameras with a frame waiting, in the order they started waiting; thread-safe."""

    def __init__(self) -> None:
        self._changed = threading.Condition()
        self._waiting: dict[str, None] = {}  # insertion-ordered: the longest-waiting camera first
        self._busy: set[str] = set()

    def arrived(self, camera: str) -> None:
        """A frame of ``camera`` arrived; a camera already waiting keeps its place."""
        with self._changed:
            self._waiting.setdefault(camera)
            self._changed.notify()

    def claim(self, timeout: float) -> str | None:
        """The longest-waiting camera that no worker has, now marked as this worker's; None if
        there is none within ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                camera = next((c for c in self._waiting if c not in self._busy), None)
                if camera is not None:
                    del self._waiting[camera]
                    self._busy.add(camera)
                    return camera
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._changed.wait(left)

    def release(self, camera: str) -> None:
        """The worker is done with ``camera``; a frame that arrived meanwhile can be claimed."""
        with self._changed:
            self._busy.discard(camera)
            if camera in self._waiting:
                self._changed.notify()
