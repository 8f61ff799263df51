"""Whether the live data can be trusted now, and when it could not: the gateway's "degraded" reasons.

A map that shows 11 people when 50 are there because the tracker fell behind must not say "all
systems ok". ``DataQuality`` watches what reaches the gateway and names what is wrong:

- **tracks late**: the newest tick arrived more than ``late_s`` after its capture time (the tracker
  or the detector falls behind; on one host, or hosts with synchronised clocks);
- **ticks missing**: consecutive ticks more than ``gap_s`` apart in capture time within the last
  ``window_s`` (the tracker skipped ticks);
- **camera down**, **camera behind** (its newest message is more than ``late_s`` old by capture
  time while it still reports), **camera dropping frames** (more than ``drop_share`` of its frames
  lost in the last ``window_s``), from the camera health book.

Each check runs at most once a second; the periods with any reason are kept for an hour, for the
dashboard's chart.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from bevflow_services.gateway.camera_health import CameraHealth
from bevflow.units import NS_PER_S


@dataclass
class DegradedPeriod:
    start_ns: int
    end_ns: int | None = None
    reasons: list[str] = field(default_factory=list)


class DataQuality:
    """Degraded reasons from ticks and camera health; the degraded periods of the last hour."""

    def __init__(self, late_s: float = 3.0, gap_s: float = 1.5, window_s: float = 30.0, drop_share: float = 0.2,
                 keep_s: float = 3600.0) -> None:
        self.late_ns, self.gap_ns, self.window_ns = int(late_s * NS_PER_S), int(gap_s * NS_PER_S), int(window_s * NS_PER_S)
        self.drop_share = drop_share
        self.keep_ns = int(keep_s * NS_PER_S)
        self._ticks: deque[tuple[int, int]] = deque()  # (capture ns, received ns), last window_s
        self._gaps: deque[tuple[int, int]] = deque()  # (received ns, gap ns) of ticks after a long gap
        self.periods: deque[DegradedPeriod] = deque()
        self._reasons: list[str] = []
        self._checked_ns = 0
        self.ticks = 0  # every tick so far, and the sum of their capture-to-arrival times, for /metrics
        self.latency_sum_ns = 0

    def tick(self, capture_ns: int, received_ns: int) -> None:
        if self._ticks and capture_ns - self._ticks[-1][0] > self.gap_ns:
            self._gaps.append((received_ns, capture_ns - self._ticks[-1][0]))
        self._ticks.append((capture_ns, received_ns))
        self.ticks += 1
        self.latency_sum_ns += received_ns - capture_ns
        while self._ticks and received_ns - self._ticks[0][1] > self.window_ns:
            self._ticks.popleft()
        while self._gaps and received_ns - self._gaps[0][0] > self.window_ns:
            self._gaps.popleft()

    def latest_ticks(self) -> list[tuple[int, int]]:
        """The newest two ticks' (capture ns, received ns), oldest first; fewer before two came."""
        return list(self._ticks)[-2:]

    def due(self, now_ns: int) -> bool:
        """Whether ``reasons`` would check again at ``now_ns`` (at most once a second)."""
        return not self._checked_ns or now_ns - self._checked_ns >= NS_PER_S

    def reasons(self, now_ns: int, cameras: list[CameraHealth]) -> list[str]:
        """What is wrong with the live data now (empty: nothing known); updates the periods."""
        if not self.due(now_ns):
            return list(self._reasons)
        self._checked_ns = now_ns
        found = self._tick_reasons(now_ns) + camera_reasons(cameras, self.late_ns, self.drop_share)
        self._record(now_ns, found)
        self._reasons = found
        return list(found)

    def _tick_reasons(self, now_ns: int) -> list[str]:
        found = []
        if self._ticks:
            capture, received = self._ticks[-1]
            if received - capture > self.late_ns:
                found.append(f"tracks arrive {(received - capture) / NS_PER_S:.1f} s after capture: the tracker or detector is behind")
        recent_gaps = [g for r, g in self._gaps if now_ns - r <= self.window_ns]
        if recent_gaps:
            found.append(f"the tracker skipped ticks: {len(recent_gaps)} gap(s) up to {max(recent_gaps) / NS_PER_S:.1f} s "
                         f"in the last {self.window_ns // NS_PER_S} s")
        return found

    def _record(self, now_ns: int, found: list[str]) -> None:
        last = self.periods[-1] if self.periods else None
        labels = {r.split(":")[0] for r in found}  # "camera north down", without the changing numbers
        if found and (last is None or last.end_ns is not None):
            self.periods.append(DegradedPeriod(now_ns, None, sorted(labels)))
        elif found and last is not None:
            last.reasons = sorted(set(last.reasons) | labels)[:10]
        elif not found and last is not None and last.end_ns is None:
            last.end_ns = now_ns
        while self.periods and self.periods[0].end_ns is not None and now_ns - self.periods[0].end_ns > self.keep_ns:
            self.periods.popleft()


def camera_reasons(cameras: list[CameraHealth], late_ns: int, drop_share: float) -> list[str]:
    """Down cameras, cameras whose newest data is old, cameras losing many frames."""
    found = []
    for c in cameras:
        if c.state == "down":
            found.append(f"camera {c.camera} down: {c.reason}")
        elif c.state == "up" and c.last_capture_ns is not None and c.last_received_ns is not None \
                and c.last_received_ns - c.last_capture_ns > late_ns:
            found.append(f"camera {c.camera} is {(c.last_received_ns - c.last_capture_ns) / NS_PER_S:.1f} s behind")
        elif c.state == "up" and c.recent_frames and c.recent_dropped / (c.recent_frames + c.recent_dropped) > drop_share:
            share = c.recent_dropped / (c.recent_frames + c.recent_dropped)
            found.append(f"camera {c.camera} lost {share:.0%} of its frames recently")
    return found
