"""What the bus feeds the calibration routes: each camera's latest frame and the projectors'
recent cylinders."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from bevflow.detections import Cylinders
from bevflow.schemas import CameraCylinders, FrameHeader

FrameFetcher = Callable[[str], "tuple[FrameHeader, np.ndarray] | None"]


class CalibrationInputs:
    """The latest frame of each camera and the projectors' recent cylinders, grouped into ticks of
    ``period_ns`` by capture time (the last ``max_ticks`` kept). Thread-safe: the bus feeds it
    from its own threads.

    Frames are large, and a still is wanted only while someone calibrates: rather than receiving
    every frame, the gateway can pass ``fetch_frame(camera)``, which waits briefly for that
    camera's next frame (None if none comes); a frame fetched or put is kept as the latest."""

    def __init__(self, period_ns: int = 100_000_000, max_ticks: int = 1200, fetch_frame: FrameFetcher | None = None) -> None:
        self.period_ns = period_ns
        self.max_ticks = max_ticks
        self.fetch_frame = fetch_frame
        self._lock = threading.Lock()
        self._frames: dict[str, tuple[FrameHeader, np.ndarray]] = {}
        self._ticks: OrderedDict[int, dict[str, Cylinders]] = OrderedDict()

    def put_frame(self, header: FrameHeader, image: np.ndarray) -> None:
        """Keep ``image`` (bgr8 HxWx3, gray8 HxW, or the 1-D bytes of a JPEG) as the camera's latest."""
        with self._lock:
            self._frames[header.camera] = (header, image)

    def latest_frame(self, camera: str, fetch: bool = True) -> tuple[FrameHeader, np.ndarray] | None:
        """The camera's newest frame: fetched now when there is a ``fetch_frame`` and ``fetch``,
        otherwise (or when none comes) the last one put or fetched."""
        if fetch and self.fetch_frame is not None:
            fetched = self.fetch_frame(camera)
            if fetched is not None:
                self.put_frame(*fetched)
        with self._lock:
            return self._frames.get(camera)

    def put_cylinders(self, message: CameraCylinders) -> None:
        slot = message.capture_ns - message.capture_ns % self.period_ns
        # Kept as arrays, not messages: two minutes of a large site's cylinders as pydantic
        # objects take hundreds of MiB. The camera index is set when a check reads them.
        cylinders = message.to_cylinders(camera_index=-1)
        with self._lock:
            self._ticks.setdefault(slot, {})[message.camera] = cylinders
            while len(self._ticks) > self.max_ticks:
                self._ticks.popitem(last=False)

    def ticks(self) -> list[dict[str, Cylinders]]:
        with self._lock:
            return [dict(t) for t in self._ticks.values()]
