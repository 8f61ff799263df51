"""Per-camera health as the gateway sees it: when each camera was last heard from, frames lost.

A camera counts as up while its messages keep arriving, down when the tracker reported it down or
nothing came for ``timeout_s``, and unknown before its first message. Frames lost are counted from
gaps in the per-camera sequence numbers; a sequence that restarts (the ingest worker restarted)
starts counting again instead of being read as a huge gap.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Literal

from bevflow.schemas import CameraHealthEvent
from bevflow.units import NS_PER_S

RECENT_NS = 30 * NS_PER_S  # the window of ``recent_frames`` and ``recent_dropped``
CameraState = Literal["up", "down", "unknown"]


@dataclass
class CameraCounters:
    received: int = 0
    dropped: int = 0
    last_seq: int | None = None
    last_capture_ns: int | None = None
    last_received_ns: int | None = None
    down_event: CameraHealthEvent | None = None
    recent: deque[tuple[int, int]] = field(default_factory=deque)  # (received ns, frames lost just before), last RECENT_NS


@dataclass(frozen=True)
class CameraHealth:
    """One camera's health at ``now_ns`` (gateway wall clock)."""

    camera: str
    state: CameraState
    reason: str
    received: int
    dropped: int
    last_seq: int | None
    last_capture_ns: int | None
    last_received_ns: int | None
    age_s: float | None
    recent_frames: int = 0  # frames received in the last 30 s
    recent_dropped: int = 0  # frames lost in the last 30 s


class CameraHealthBook:
    """Counters for a fixed set of cameras (the site's); messages from other cameras are refused."""

    def __init__(self, cameras: list[str], timeout_s: float = 5.0) -> None:
        self.timeout_ns = int(timeout_s * NS_PER_S)
        self._counters = {camera: CameraCounters() for camera in cameras}

    def __contains__(self, camera: str) -> bool:
        return camera in self._counters

    def record_frame(self, camera: str, seq: int, capture_ns: int, received_ns: int) -> bool:
        """Count one message of ``camera``; False (and nothing counted) for an unknown camera."""
        c = self._counters.get(camera)
        if c is None:
            return False
        if c.last_seq is not None and seq == c.last_seq:
            return True  # the same frame seen through another message kind
        lost = seq - c.last_seq - 1 if c.last_seq is not None and seq > c.last_seq else 0
        c.dropped += lost
        c.recent.append((received_ns, lost))
        while c.recent and received_ns - c.recent[0][0] > RECENT_NS:
            c.recent.popleft()
        c.received += 1
        c.last_seq = seq
        c.last_capture_ns = capture_ns
        c.last_received_ns = received_ns
        return True

    def record_event(self, event: CameraHealthEvent) -> bool:
        """Apply a camera_down / camera_up event; False for an unknown camera."""
        c = self._counters.get(event.camera)
        if c is None:
            return False
        going_down = event.type == "camera_down" and event.end_ns is None
        c.down_event = event if going_down else None
        return True

    def health(self, camera: str, now_ns: int) -> CameraHealth:
        c = self._counters[camera]
        age_s = None if c.last_received_ns is None else max(0.0, (now_ns - c.last_received_ns) / NS_PER_S)
        if c.down_event is not None:
            state: CameraState = "down"
            reason = c.down_event.reason or "reported down by the tracker"
        elif c.last_received_ns is None:
            state, reason = "unknown", "no message yet"
        elif now_ns - c.last_received_ns > self.timeout_ns:
            state, reason = "down", f"no message for {age_s:.1f} s"
        else:
            state, reason = "up", ""
        return CameraHealth(
            camera=camera,
            state=state,
            reason=reason,
            received=c.received,
            dropped=c.dropped,
            last_seq=c.last_seq,
            last_capture_ns=c.last_capture_ns,
            last_received_ns=c.last_received_ns,
            age_s=age_s,
            recent_frames=sum(1 for r, _ in c.recent if now_ns - r <= RECENT_NS),
            recent_dropped=sum(lost for r, lost in c.recent if now_ns - r <= RECENT_NS),
        )
