"""The most crowded time intervals (paper 3.8): when a zone held more than its crowded level.

A count series is read sample-and-hold: each count holds until the next sample. An interval starts
at the first sample with count > ``level`` and ends at the first sample back at or below it (or at
the last sample, if the series ends crowded). Two intervals are merged when the dip between them
is no longer than ``min_gap_ns`` (measured from the end of one to the start of the next), so a
crowd thinning for a moment does not split the afternoon rush in two. After merging, intervals
shorter than ``min_duration_ns`` are dropped. ``peak`` is the highest count and ``peak_ns`` the
first time it was reached.

``crowded_intervals`` does this for a whole recorded series; ``CrowdedIntervalTracker`` does the
same live, one sample at a time, and gives the same intervals.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from bevflow.analytics.positions import Clock
from bevflow.schemas import CrowdedInterval


def _check_options(level: int, min_gap_ns: int, min_duration_ns: int) -> None:
    for name, value in (("level", level), ("min_gap_ns", min_gap_ns), ("min_duration_ns", min_duration_ns)):
        if value < 0:
            raise ValueError(f"{name} must be >= 0, got {value}")


def crowded_intervals(
    times_ns: ArrayLike,
    counts: ArrayLike,
    level: int,
    min_gap_ns: int = 0,
    min_duration_ns: int = 0,
    zone: str | None = None,
) -> list[CrowdedInterval]:
    """The crowded intervals of a count series, in time order (rules in the module docstring).

    >>> found = crowded_intervals([0, 1, 2, 3, 4], [1, 5, 2, 6, 1], level=4, min_gap_ns=1)
    >>> [(i.start_ns, i.end_ns, i.peak, i.peak_ns) for i in found]
    [(1, 4, 6, 3)]
    """
    _check_options(level, min_gap_ns, min_duration_ns)
    t = np.asarray(times_ns, dtype=np.int64).reshape(-1)
    c = np.asarray(counts).reshape(-1)
    if len(t) != len(c):
        raise ValueError(f"{len(t)} times but {len(c)} counts")
    if np.any(np.diff(t) < 0):
        raise ValueError("times must not decrease")
    crowded = c > level
    if not crowded.any():
        return []
    edges = np.diff(np.concatenate([[0], crowded.astype(np.int8), [0]]))
    run_start = np.flatnonzero(edges == 1)  # first crowded sample of each run
    run_stop = np.flatnonzero(edges == -1)  # the sample after the run's last one
    run_end_ns = t[np.minimum(run_stop, len(t) - 1)]
    splits = np.concatenate([[True], t[run_start[1:]] - run_end_ns[:-1] > min_gap_ns])
    first = np.flatnonzero(splits)
    last = np.concatenate([first[1:] - 1, [len(run_start) - 1]])

    intervals = []
    for a, b in zip(run_start[first], last, strict=True):
        start_ns, end_ns = int(t[a]), int(run_end_ns[b])
        if end_ns - start_ns < min_duration_ns:
            continue
        k = a + int(np.argmax(c[a : run_stop[b]]))
        intervals.append(
            CrowdedInterval(zone=zone, level=level, start_ns=start_ns, end_ns=end_ns, peak=int(c[k]), peak_ns=int(t[k]))
        )
    return intervals


class CrowdedIntervalTracker:
    """``crowded_intervals`` one sample at a time, for live use.

    An interval is reported by ``update`` once it is certainly over, that is once the dip after it
    has lasted longer than ``min_gap_ns``; until then ``current`` shows it with ``end_ns`` None.

    >>> tracker = CrowdedIntervalTracker(level=4, min_gap_ns=1)
    >>> [tracker.update(t, c) for t, c in enumerate([1, 5, 2, 6, 1, 1, 1])][-1].end_ns
    4
    """

    def __init__(self, level: int, min_gap_ns: int = 0, min_duration_ns: int = 0, zone: str | None = None) -> None:
        _check_options(level, min_gap_ns, min_duration_ns)
        self.level, self.min_gap_ns, self.min_duration_ns, self.zone = level, min_gap_ns, min_duration_ns, zone
        self._clock = Clock()
        self._start_ns: int | None = None
        self._dip_ns: int | None = None  # when the count fell back to the level, while it is still there
        self._peak, self._peak_ns = 0, 0

    @property
    def current(self) -> CrowdedInterval | None:
        """The interval in progress (possibly in a dip that may still be merged), or None."""
        return None if self._start_ns is None else self._interval(None)

    def update(self, time_ns: int, count: int) -> CrowdedInterval | None:
        """Take one sample; returns the interval this sample proved finished, if it was long enough."""
        t = self._clock.advance(time_ns)
        finished = None
        if self._dip_ns is not None and t - self._dip_ns > self.min_gap_ns:
            finished = self._close(self._dip_ns)
        if count > self.level:
            if self._start_ns is None:
                self._start_ns, self._peak, self._peak_ns = t, int(count), t
            elif count > self._peak:
                self._peak, self._peak_ns = int(count), t
            self._dip_ns = None
        elif self._start_ns is not None and self._dip_ns is None:
            self._dip_ns = t
        return finished

    def flush(self) -> CrowdedInterval | None:
        """Close the interval in progress at the end of the series (as ``crowded_intervals`` would)."""
        if self._start_ns is None:
            return None
        assert self._clock.last_ns is not None
        return self._close(self._dip_ns if self._dip_ns is not None else self._clock.last_ns)

    def _close(self, end_ns: int) -> CrowdedInterval | None:
        interval = self._interval(end_ns)
        self._start_ns = self._dip_ns = None
        return interval if end_ns - interval.start_ns >= self.min_duration_ns else None

    def _interval(self, end_ns: int | None) -> CrowdedInterval:
        assert self._start_ns is not None
        return CrowdedInterval(
            zone=self.zone,
            level=self.level,
            start_ns=self._start_ns,
            end_ns=end_ns,
            peak=self._peak,
            peak_ns=self._peak_ns,
        )
