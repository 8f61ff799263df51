"""Group per-camera results into site-wide ticks, in capture-time order.

Cameras are not synchronised and their results reach the tracker late, out of order, or not at
all. The tracker needs one set of cylinders per tick, in time order. ``TickAssembler`` puts each
camera message into the tick slot of its capture time and releases a slot once every expected
camera has reported for it or for a later slot, or once ``max_wait_ns`` has passed since the slot
ended, whichever comes first. A camera's results arrive in capture order, so one that has
reported a later capture has nothing more for the slot: a frame its detector skipped (latest
frame wins) costs no waiting. Only cameras heard from in the last ``stale_ns`` are waited for, so
a dead camera delays the site by at most ``max_wait_ns`` for a few seconds, then not at all, and
never stops it.

What does not fit is dropped and counted, never raised: a message for a slot already released
(too late), a timestamp far in the future (a camera clock gone wrong), an unknown camera.

>>> a = TickAssembler(["a", "b"], period_ns=100, max_wait_ns=50)
>>> a.push("a", 1_010, "A1", now_ns=1_020)
'accepted'
>>> a.push("b", 1_030, "B1", now_ns=1_040)
'accepted'
>>> [(t.start_ns, sorted(t.items)) for t in a.pop_ready(now_ns=1_040)]
[(1000, ['a', 'b'])]
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Generic, Literal, TypeVar

T = TypeVar("T")
PushResult = Literal["accepted", "late", "future", "unknown_camera"]


@dataclass
class Tick(Generic[T]):
    """One slot of site time: [start_ns, start_ns + period). ``items`` maps camera id to its
    newest message in the slot; ``capture_ns`` to that message's capture time."""

    start_ns: int
    period_ns: int
    items: dict[str, T] = field(default_factory=dict)
    capture_ns: dict[str, int] = field(default_factory=dict)

    @property
    def end_ns(self) -> int:
        return self.start_ns + self.period_ns

    @property
    def time_ns(self) -> int:
        """The tick's time: the latest capture time in it (what the tracker predicts to)."""
        return max(self.capture_ns.values(), default=self.start_ns)


class TickAssembler(Generic[T]):
    def __init__(
        self,
        cameras: list[str],
        period_ns: int = 100_000_000,
        max_wait_ns: int = 150_000_000,
        max_future_ns: int = 2_000_000_000,
        stale_ns: int = 2_000_000_000,
    ) -> None:
        if period_ns <= 0 or max_wait_ns < 0:
            raise ValueError("period_ns must be positive and max_wait_ns non-negative")
        self.cameras = frozenset(cameras)
        self.period_ns = period_ns
        self.max_wait_ns = max_wait_ns
        self.max_future_ns = max_future_ns
        self.stale_ns = stale_ns
        self._heard_ns: dict[str, int] = {}  # camera -> arrival time of its last accepted or late message
        self._newest_ns: dict[str, int] = {}  # camera -> its latest capture time accepted
        self._slots: dict[int, Tick[T]] = {}
        self._released_until_ns: int | None = None  # every slot starting before this is gone
        self.counts: Counter[str] = Counter()

    def push(self, camera: str, capture_ns: int, item: T, now_ns: int) -> PushResult:
        result = self._classify(camera, capture_ns, now_ns)
        self.counts[result] += 1
        if result in ("accepted", "late"):
            # A late camera is alive, only slow: it must still be waited for, or once it falls
            # out of the live set every tick closes without it and all it sends arrives late.
            self._heard_ns[camera] = now_ns
        if result != "accepted":
            return result
        self._newest_ns[camera] = max(capture_ns, self._newest_ns.get(camera, capture_ns))
        start = capture_ns - capture_ns % self.period_ns
        slot = self._slots.setdefault(start, Tick(start, self.period_ns))
        if capture_ns >= slot.capture_ns.get(camera, -1):
            slot.items[camera] = item
            slot.capture_ns[camera] = capture_ns
        return result

    def _classify(self, camera: str, capture_ns: int, now_ns: int) -> PushResult:
        if camera not in self.cameras:
            return "unknown_camera"
        if capture_ns > now_ns + self.max_future_ns:
            return "future"
        if self._released_until_ns is not None and capture_ns < self._released_until_ns:
            return "late"
        return "accepted"

    def pop_ready(self, now_ns: int) -> list[Tick[T]]:
        """Slots that are complete or have waited long enough, oldest first.

        Releasing a slot also releases every older one, so ticks always leave in time order."""
        ready_until: int | None = None
        live = {c for c, heard in self._heard_ns.items() if now_ns - heard <= self.stale_ns}
        for start in sorted(self._slots):
            slot = self._slots[start]
            complete = all(c in slot.items or self._newest_ns.get(c, -1) >= slot.end_ns for c in live)
            expired = now_ns >= slot.end_ns + self.max_wait_ns
            if complete or expired:
                ready_until = slot.end_ns
        if ready_until is None:
            return []
        out = [self._slots.pop(s) for s in sorted(self._slots) if s < ready_until]
        self._released_until_ns = ready_until
        return out

    def flush(self) -> list[Tick[T]]:
        """Every pending slot, oldest first (at shutdown or the end of a recording)."""
        out = [self._slots.pop(s) for s in sorted(self._slots)]
        if out:
            self._released_until_ns = out[-1].end_ns
        return out

    @property
    def pending(self) -> int:
        return len(self._slots)
