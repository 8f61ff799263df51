"""Whether a camera's frame shows anything new since the frame the detector last ran on.

A camera over an empty corridor, or over people sitting still, sends the same picture ten times a
second; running the detector on each costs a site most of its CPU for nothing. ``StillFrames``
keeps a small grey thumbnail of each camera's last detected frame (area-averaged, which also
averages sensor noise away) and calls a new frame still when fewer than ``min_pixels`` of its
thumbnail pixels differ from that one by more than ``level`` grey levels. A person walking
changes a few thumbnail pixels by tens of levels from one frame to the next; noise and flicker
change none by that much. A still frame reuses the last boxes; the reference stays the frame
last detected on, so slow changes add up until they count, and every camera is detected again
at least every ``max_age_s`` whatever happens.

>>> still = StillFrames()
>>> floor = np.full((240, 320, 3), 90, np.uint8)
>>> still.is_still("a", floor, 0)  # nothing to compare with yet
False
>>> still.is_still("a", floor, 100_000_000)
True
>>> walker = floor.copy(); walker[100:130, 150:165] = 20  # a dark person, 15 x 30 px
>>> still.is_still("a", walker, 200_000_000)
False
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.units import NS_PER_S

THUMB_PX = 96  # the long side of the thumbnail
LEVEL = 10  # grey levels a thumbnail pixel must change by to count
MIN_PIXELS = 2
MAX_AGE_S = 1.0


@dataclass(frozen=True)
class _Reference:
    thumb: NDArray[np.uint8]
    capture_ns: int


class StillFrames:
    """Per camera: is this frame still? Frames that are not become the new reference."""

    def __init__(self, level: int = LEVEL, min_pixels: int = MIN_PIXELS, max_age_s: float = MAX_AGE_S,
                 thumb_px: int = THUMB_PX) -> None:  # fmt: skip
        self.level, self.min_pixels, self.thumb_px = level, min_pixels, thumb_px
        self.max_age_ns = int(max_age_s * NS_PER_S)
        self._last: dict[str, _Reference] = {}

    def is_still(self, camera: str, image_bgr: NDArray[np.uint8], capture_ns: int) -> bool:
        thumb = self._thumbnail(image_bgr)
        last = self._last.get(camera)
        if last is not None and last.thumb.shape == thumb.shape and 0 <= capture_ns - last.capture_ns <= self.max_age_ns:
            changed = int(np.count_nonzero(cv2.absdiff(thumb, last.thumb) > self.level))
            if changed < self.min_pixels:
                return True
        self._last[camera] = _Reference(thumb, capture_ns)
        return False

    def forget(self, camera: str) -> None:
        """Detect the camera's next frame whatever it shows (its last boxes are gone)."""
        self._last.pop(camera, None)

    def _thumbnail(self, image_bgr: NDArray[np.uint8]) -> NDArray[np.uint8]:
        h, w = image_bgr.shape[:2]
        k = self.thumb_px / max(h, w, 1)
        size = (max(1, round(w * k)), max(1, round(h * k)))
        grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY) if image_bgr.ndim == 3 else image_bgr
        return np.asarray(cv2.resize(grey, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
