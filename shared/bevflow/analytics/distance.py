"""Social-distance violations over time (paper 3.8, with the temporal rule its future work asks for).

A pair of tracks, keyed by (smaller id, larger id), moves through these states:

- **close**: the two came closer than ``social_distance_m`` (strictly). Nothing is published yet:
  people brushing past each other are not a violation.
- **violation**: they stayed close for ``violation_min_duration_s``. A ``DistanceViolation`` is
  published with ``start_ns`` = the first tick they were close and ``end_ns`` None.
- **group**: they stayed close for ``group_after_s`` (a family, a couple). An open violation is
  closed at that tick with ``group=True``, and the pair raises nothing more while both tracks
  exist, even if they part for a while and come back together. ``group_after_s=None`` turns
  this off; a ``group_after_s`` shorter than ``violation_min_duration_s`` means no pair that stays
  together ever alerts.

"Stayed close" means close at every tick. Once tracked, a pair counts as close until its distance
exceeds ``social_distance_m + release_margin_m``: the margin (default 0.2 m, about the feet
position error the paper reports for camera pairs) stops a pair standing right at the limit from
starting and ending alerts every few ticks. A pair ends at the first tick it is farther apart than
that, or one of its tracks is missing; ``end_ns`` is that tick's time. To close every open alert
(at shutdown), call ``update`` with no tracks.

The event records the minimum distance over the whole episode, the midpoint of the pair at that
closest approach (``position``), and the first zone holding that midpoint.

Pairs come from a k-d tree (``cKDTree.query_pairs``), and the per-pair state lives in sorted numpy
columns, so a tick costs O(N log N + P log P) for N people and P close pairs with no Python loop
over pairs; only published events are built one by one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from bevflow.analytics.positions import (
    Clock,
    FloatArray,
    IntArray,
    check_positions,
    pair_ids,
    pair_keys,
    seconds_to_ns,
)
from bevflow.analytics.zones import ZoneIndex
from bevflow.schemas import DistanceViolation
from bevflow.site import Thresholds, Zone

CLOSE, VIOLATION, GROUP = 0, 1, 2


@dataclass
class _Pairs:
    """Per-pair state as columns sorted by ``key``."""

    key: IntArray
    state: NDArray[np.int8]
    first_ns: IntArray
    min_d: FloatArray
    min_xy: FloatArray

    @classmethod
    def empty(cls) -> _Pairs:
        return cls(
            key=np.zeros(0, np.int64),
            state=np.zeros(0, np.int8),
            first_ns=np.zeros(0, np.int64),
            min_d=np.zeros(0),
            min_xy=np.zeros((0, 2)),
        )

    def take(self, index: NDArray[np.intp]) -> _Pairs:
        return _Pairs(self.key[index], self.state[index], self.first_ns[index], self.min_d[index], self.min_xy[index])

    @staticmethod
    def concat(a: _Pairs, b: _Pairs) -> _Pairs:
        merged = _Pairs(
            np.concatenate([a.key, b.key]),
            np.concatenate([a.state, b.state]),
            np.concatenate([a.first_ns, b.first_ns]),
            np.concatenate([a.min_d, b.min_d]),
            np.concatenate([a.min_xy, b.min_xy]),
        )
        return merged.take(np.argsort(merged.key, kind="stable"))


def _gather(column: NDArray[Any], slot: IntArray, found: NDArray[np.bool_], fill: float) -> NDArray[Any]:
    """``column[slot]`` where ``found``, ``fill`` elsewhere (``column`` may be empty)."""
    out = np.full((len(slot), *column.shape[1:]), fill, dtype=column.dtype)
    out[found] = column[slot[found]]
    return out


class DistanceMonitor:
    """Turns per-tick positions into ``DistanceViolation`` start and end events (rules above).

    >>> from bevflow.site import Thresholds
    >>> m = DistanceMonitor(Thresholds(violation_min_duration_s=1.0))
    >>> [len(m.update(t * 500_000_000, [1, 2], [[0, 0], [1, 0]])) for t in range(4)]
    [0, 0, 1, 0]
    >>> m.current_pairs.tolist()
    [[1, 2]]
    """

    def __init__(self, thresholds: Thresholds, zones: Sequence[Zone] = (), release_margin_m: float = 0.2) -> None:
        if release_margin_m < 0:
            raise ValueError(f"release_margin_m must be >= 0, got {release_margin_m}")
        self.limit_m = float(thresholds.social_distance_m)
        self.release_m = self.limit_m + float(release_margin_m)
        self.min_duration_ns = seconds_to_ns(thresholds.violation_min_duration_s)
        self.group_after_ns = None if thresholds.group_after_s is None else seconds_to_ns(thresholds.group_after_s)
        self._zones = ZoneIndex(zones)
        self._pairs = _Pairs.empty()
        self._clock = Clock()

    @property
    def current_pairs(self) -> IntArray:
        """(K, 2) track-id pairs (smaller id first) whose violation is open now."""
        return pair_ids(self._pairs.key[self._pairs.state == VIOLATION])

    @property
    def groups(self) -> IntArray:
        """(K, 2) track-id pairs taken as groups and so exempt from alerts."""
        return pair_ids(self._pairs.key[self._pairs.state == GROUP])

    def reset(self) -> None:
        """Forget every pair and the clock, without publishing anything."""
        self._pairs = _Pairs.empty()
        self._clock = Clock()

    def update(self, time_ns: int, ids: ArrayLike, xy: ArrayLike) -> list[DistanceViolation]:
        """Advance to ``time_ns`` with the tracks present now; returns the events that started or
        ended at this tick (ends first)."""
        ids_arr, xy_arr = check_positions(ids, xy)
        t = self._clock.advance(time_ns)
        key, dist, i, j = self._near_pairs(ids_arr, xy_arr)

        old = self._pairs
        slot = np.searchsorted(old.key, key)
        known = slot < len(old.key)
        known[known] = old.key[slot[known]] == key[known]
        held = np.zeros(len(old.key), dtype=bool)
        held[slot[known]] = True
        # Groups outlive separation; they are forgotten only when one of the two tracks is gone.
        apart = np.flatnonzero(~held & (old.state == GROUP))
        if len(apart):
            apart = apart[np.isin(pair_ids(old.key[apart]), ids_arr).all(axis=1)]
        ended = old.take(np.flatnonzero(~held & (old.state == VIOLATION)))

        # The pairs close now: those already followed, and new ones strictly inside the limit.
        rows = np.flatnonzero(known | (dist < self.limit_m))
        was, slot = known[rows], slot[rows]
        dist, mid = dist[rows], (xy_arr[i[rows]] + xy_arr[j[rows]]) / 2.0
        prev_d = _gather(old.min_d, slot, was, np.inf)
        nearer = dist < prev_d
        pairs = _Pairs(
            key=key[rows],
            state=_gather(old.state, slot, was, CLOSE),
            first_ns=_gather(old.first_ns, slot, was, t),
            min_d=np.where(nearer, dist, prev_d),
            min_xy=np.where(nearer[:, None], mid, _gather(old.min_xy, slot, was, 0.0)),
        )
        pairs = _Pairs.concat(pairs, old.take(apart))
        grouped, started = self._promote(pairs, t)
        self._pairs = pairs
        return self._events([(ended, t, False), (grouped, t, True), (started, None, False)])

    def _near_pairs(self, ids: IntArray, xy: FloatArray) -> tuple[IntArray, FloatArray, IntArray, IntArray]:
        """Keys and distances of every pair within the release distance, and the pair's rows."""
        if len(ids) < 2:
            none = np.zeros(0, np.int64)
            return none, np.zeros(0), none, none
        ij = cKDTree(xy, balanced_tree=False, compact_nodes=False).query_pairs(self.release_m, output_type="ndarray")
        i, j = ij[:, 0], ij[:, 1]
        dist = np.hypot(*(xy[i] - xy[j]).T)
        a, b = ids[i], ids[j]
        return pair_keys(np.minimum(a, b), np.maximum(a, b)), dist, i, j

    def _promote(self, pairs: _Pairs, t: int) -> tuple[_Pairs, _Pairs]:
        """Promote the pairs close long enough, in place; returns the violations closed by becoming
        groups and the violations that start now."""
        age = t - pairs.first_ns
        to_group = (pairs.state != GROUP) & (age >= self.group_after_ns if self.group_after_ns is not None else False)
        to_violation = (pairs.state == CLOSE) & (age >= self.min_duration_ns) & ~to_group
        grouped = pairs.take(np.flatnonzero(to_group & (pairs.state == VIOLATION)))
        pairs.state[to_group] = GROUP
        pairs.state[to_violation] = VIOLATION
        return grouped, pairs.take(np.flatnonzero(to_violation))

    def _events(self, batches: list[tuple[_Pairs, int | None, bool]]) -> list[DistanceViolation]:
        """Messages for batches of (pairs, end_ns, group), with one zone look-up for them all."""
        where = np.concatenate([p.min_xy for p, _, _ in batches])
        if len(where) == 0:
            return []
        zones = iter(self._zones.first_zone(where) if len(self._zones) else [None] * len(where))
        events = []
        for pairs, end_ns, group in batches:
            lo_hi, first_ns = pair_ids(pairs.key).tolist(), pairs.first_ns.tolist()
            rows = zip(lo_hi, first_ns, pairs.min_d.tolist(), pairs.min_xy.tolist(), strict=True)
            events += [
                DistanceViolation(
                    id=f"distance-{lo}-{hi}-{start}",
                    start_ns=start,
                    end_ns=end_ns,
                    zone=next(zones),
                    tracks=[lo, hi],
                    min_distance_m=d,
                    limit_m=self.limit_m,
                    position=(x, y),
                    group=group,
                )
                for (lo, hi), start, d, (x, y) in rows
            ]
        return events
