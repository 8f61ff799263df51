"""Where each track has been: a bounded history of feet positions, for tracing and trajectories.

Memory is bounded by construction: every track gets a ring buffer of ``max_points`` samples, at most
``max_tracks`` tracks are kept (16 bytes a sample, so 600 points x 4096 tracks is at most 39 MB),
and a track unseen for ``retire_after_s`` is forgotten. When the table is full, the track seen
least recently makes room for a new one.

Sampling is global, not per track: the first tick of every ``sample_period_s`` bucket of capture
time is stored for every track present, and the other ticks are skipped. Every track's samples
therefore fall on the same timestamps, which lets ``bevflow.analytics.contacts`` compare two tracks
sample by sample without interpolating.

All per-tick work is vectorised over tracks: slots are found with a sorted id index and written with
fancy indexing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from bevflow.analytics.positions import Clock, FloatArray, IntArray, check_positions, seconds_to_ns
from bevflow.schemas import TrajectoryPoint

FREE = -1


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One track's stored samples, oldest first: ``times_ns`` (K,) and feet ``xy`` (K, 2) metres."""

    track_id: int
    times_ns: IntArray
    xy: FloatArray

    def __len__(self) -> int:
        return len(self.times_ns)

    def to_points(self) -> list[TrajectoryPoint]:
        times, xy = self.times_ns.tolist(), self.xy.tolist()
        return [TrajectoryPoint(time_ns=t, xy=(x, y)) for t, (x, y) in zip(times, xy, strict=True)]


class TrackHistory:
    """Recent trajectories of every track (bounds and sampling rule in the module docstring).

    >>> history = TrackHistory(sample_period_s=1.0)
    >>> for t in range(4):
    ...     _ = history.update(t * 500_000_000, [3], [[t, 0.0]])
    >>> history.trajectory(3).xy[:, 0].tolist()
    [0.0, 2.0]
    """

    def __init__(
        self,
        max_points: int = 600,
        sample_period_s: float = 0.5,
        retire_after_s: float = 600.0,
        max_tracks: int = 4096,
    ) -> None:
        if max_points < 1 or max_tracks < 1:
            raise ValueError("max_points and max_tracks must be at least 1")
        if sample_period_s < 0 or retire_after_s <= 0:
            raise ValueError("sample_period_s must be >= 0 and retire_after_s > 0")
        self.max_points, self.max_tracks = max_points, max_tracks
        self.sample_period_ns = seconds_to_ns(sample_period_s)
        self.retire_after_ns = seconds_to_ns(retire_after_s)
        self.skipped = 0  # samples not stored because more than max_tracks tracks were present at once
        self._clock = Clock()
        self._last_bucket: int | None = None
        self._ids = np.zeros(0, np.int64)
        self._times = np.zeros((0, max_points), np.int64)
        self._xy = np.zeros((0, max_points, 2), np.float32)
        self._head = np.zeros(0, np.int64)  # next ring position to write
        self._count = np.zeros(0, np.int64)
        self._last_seen = np.zeros(0, np.int64)
        self._grow(min(64, max_tracks))

    def _grow(self, slots: int) -> None:
        """Grow the tables to ``slots`` rows, keeping what they hold."""
        extra = slots - len(self._ids)
        self._ids = np.concatenate([self._ids, np.full(extra, FREE, np.int64)])
        self._times = np.concatenate([self._times, np.zeros((extra, self.max_points), np.int64)])
        self._xy = np.concatenate([self._xy, np.zeros((extra, self.max_points, 2), np.float32)])
        self._head = np.concatenate([self._head, np.zeros(extra, np.int64)])
        self._count = np.concatenate([self._count, np.zeros(extra, np.int64)])
        self._last_seen = np.concatenate([self._last_seen, np.zeros(extra, np.int64)])
        self._reindex()

    def _reindex(self) -> None:
        used = np.flatnonzero(self._ids != FREE)
        order = np.argsort(self._ids[used])
        self._sorted_ids, self._sorted_slots = self._ids[used][order], used[order]

    def __len__(self) -> int:
        return len(self._sorted_ids)

    def __contains__(self, track_id: object) -> bool:
        return isinstance(track_id, (int, np.integer)) and self._slot_of(int(track_id)) is not None

    @property
    def track_ids(self) -> IntArray:
        """Ids of the tracks with a stored history, ascending."""
        return self._sorted_ids.copy()

    @property
    def nbytes(self) -> int:
        """Memory held by the sample tables now (it grows up to the bound, never past it)."""
        return self._times.nbytes + self._xy.nbytes

    def update(self, time_ns: int, ids: ArrayLike, xy: ArrayLike) -> bool:
        """Record the tracks present at ``time_ns`` if this tick opens a new sample period; returns
        whether it was stored."""
        t = self._clock.advance(time_ns)
        bucket = t // self.sample_period_ns if self.sample_period_ns else t
        if bucket == self._last_bucket:
            return False
        ids_arr, xy_arr = check_positions(ids, xy)
        self._last_bucket = bucket
        self._retire(t)
        slots, stored = self._slots_for(ids_arr)
        head = self._head[slots]
        self._times[slots, head] = t
        self._xy[slots, head] = xy_arr[stored]
        self._head[slots] = (head + 1) % self.max_points
        self._count[slots] = np.minimum(self._count[slots] + 1, self.max_points)
        self._last_seen[slots] = t
        return True

    def _retire(self, t: int) -> None:
        stale = (self._ids != FREE) & (t - self._last_seen > self.retire_after_ns)
        if stale.any():
            self._free(np.flatnonzero(stale))

    def _free(self, slots: IntArray) -> None:
        self._ids[slots] = FREE
        self._head[slots] = 0
        self._count[slots] = 0
        self._reindex()

    def _slots_for(self, ids: IntArray) -> tuple[IntArray, IntArray]:
        """Slots of ``ids`` (new tracks get one), and which rows of ``ids`` have a slot."""
        pos = np.searchsorted(self._sorted_ids, ids)
        known = pos < len(self._sorted_ids)
        known[known] = self._sorted_ids[pos[known]] == ids[known]
        new = np.flatnonzero(~known)
        if len(new):
            free = self._free_slots(len(new), present=ids)
            if len(free) < len(new):
                self.skipped += len(new) - len(free)
                new = new[: len(free)]
            self._ids[free] = ids[new]
            self._reindex()
            pos = np.searchsorted(self._sorted_ids, ids)
            known = pos < len(self._sorted_ids)
            known[known] = self._sorted_ids[pos[known]] == ids[known]
        stored = np.flatnonzero(known)
        return self._sorted_slots[pos[stored]], stored

    def _free_slots(self, n: int, present: IntArray) -> IntArray:
        """``n`` free slots if possible: grow the tables, then evict the tracks seen least recently."""
        free = np.flatnonzero(self._ids == FREE)
        if len(free) < n and len(self._ids) < self.max_tracks:
            self._grow(min(self.max_tracks, max(2 * len(self._ids), len(self._ids) + n - len(free))))
            free = np.flatnonzero(self._ids == FREE)
        if len(free) < n:
            absent = np.flatnonzero((self._ids != FREE) & ~np.isin(self._ids, present))
            evict = absent[np.argsort(self._last_seen[absent], kind="stable")][: n - len(free)]
            self._free(evict)
            free = np.flatnonzero(self._ids == FREE)
        return free[:n]

    def _slot_of(self, track_id: int) -> int | None:
        pos = int(np.searchsorted(self._sorted_ids, track_id))
        if pos < len(self._sorted_ids) and self._sorted_ids[pos] == track_id:
            return int(self._sorted_slots[pos])
        return None

    def trajectory(self, track_id: int) -> Trajectory:
        """The stored samples of ``track_id``, oldest first; KeyError if it has none."""
        slot = self._slot_of(int(track_id))
        if slot is None:
            raise KeyError(f"no history for track {track_id}")
        n, head = self._count[slot], self._head[slot]
        order = (head - n + np.arange(n)) % self.max_points
        return Trajectory(int(track_id), self._times[slot, order].copy(), self._xy[slot, order].astype(np.float64))

    def samples(self) -> tuple[IntArray, IntArray, FloatArray]:
        """Every stored sample of every track: track ids (M,), times (M,), xy (M, 2)."""
        slots = self._sorted_slots
        # Ring position k holds a valid sample when it is among the last ``count`` written.
        age = (self._head[slots, None] - 1 - np.arange(self.max_points)) % self.max_points
        valid = age < self._count[slots, None]
        rows, cols = np.nonzero(valid)
        return self._ids[slots[rows]], self._times[slots[rows], cols], self._xy[slots[rows], cols].astype(np.float64)
