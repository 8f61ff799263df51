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

With velocities (the tracker's, passed to ``update``) a pair can also become a group by **walking
together**. At a tick two people walk together when both move faster than ``walk_speed_mps`` and
their relative velocity, smoothed over ``velocity_smoothing_s``, is below ``walk_tolerance_mps``
(same direction, same pace). A stretch of walking together forgives lapses of up to
``walk_grace_s`` (a step aside, a noisy velocity estimate) and ends at once when the pair's
relative position wanders more than ``walk_drift_m`` from where it began: a group keeps its
formation, while a stranger overtaking slowly does not. Then:

- a close pair that walks together for ``group_walk_s`` becomes a **group**, as after
  ``group_after_s`` (an open violation is withdrawn with ``group=True``);
- while a stretch lasts, the violation of a close pair is **held back**, so a couple walking side
  by side from the start never raises one; when the stretch ends short of ``group_walk_s`` (one
  stops, they turn apart) with the pair still close, the violation is raised at that tick if they
  have been close for ``violation_min_duration_s``, ``start_ns`` being the first tick they were.

People standing close (a queue of strangers) never walk together: they are alerted after
``violation_min_duration_s`` and grouped only after ``group_after_s``, as without velocities.
Without velocities, or with ``group_walk_s`` None, walking changes nothing.

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
from dataclasses import dataclass, fields
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
from bevflow.units import NS_PER_S

CLOSE, VIOLATION, GROUP = 0, 1, 2
NO_WALK = -1  # walk_from_ns of a pair not walking together now


@dataclass
class _Pairs:
    """Per-pair state as columns sorted by ``key``."""

    key: IntArray
    state: NDArray[np.int8]
    first_ns: IntArray
    min_d: FloatArray
    min_xy: FloatArray
    rel_v: FloatArray  # (P, 2) smoothed velocity of the larger id relative to the smaller
    walk_from_ns: IntArray  # start of the current walking-together stretch, or NO_WALK
    walk_last_ns: IntArray  # last tick of that stretch
    walk_anchor: FloatArray  # (P, 2) position of the larger id relative to the smaller when it began

    @classmethod
    def empty(cls) -> _Pairs:
        return cls(
            key=np.zeros(0, np.int64),
            state=np.zeros(0, np.int8),
            first_ns=np.zeros(0, np.int64),
            min_d=np.zeros(0),
            min_xy=np.zeros((0, 2)),
            rel_v=np.zeros((0, 2)),
            walk_from_ns=np.zeros(0, np.int64),
            walk_last_ns=np.zeros(0, np.int64),
            walk_anchor=np.zeros((0, 2)),
        )

    def take(self, index: NDArray[np.intp]) -> _Pairs:
        return _Pairs(*(getattr(self, f.name)[index] for f in fields(self)))

    @staticmethod
    def concat(a: _Pairs, b: _Pairs) -> _Pairs:
        merged = _Pairs(*(np.concatenate([getattr(a, f.name), getattr(b, f.name)]) for f in fields(a)))
        return merged.take(np.argsort(merged.key, kind="stable"))


def _check_velocity(velocity: ArrayLike, n: int) -> FloatArray:
    """``velocity`` as (N, 2) float64, or a ValueError saying what is wrong."""
    v = np.asarray(velocity, dtype=np.float64)
    if v.size == 0:
        v = v.reshape(0, 2)
    if v.shape != (n, 2):
        raise ValueError(f"velocities must be an (N, 2) array of m/s for the {n} tracks, got shape {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError("velocities must be finite")
    return v


def _relative_motion(
    ids: IntArray, xy: FloatArray, velocity: FloatArray, i: IntArray, j: IntArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """For pairs of rows (i, j): the position and velocity of the larger id relative to the
    smaller (a sign that does not depend on row order), and the speed of the slower of the two."""
    swapped = (ids[i] > ids[j])[:, None]
    offset = np.where(swapped, xy[i] - xy[j], xy[j] - xy[i])
    relative = np.where(swapped, velocity[i] - velocity[j], velocity[j] - velocity[i])
    slower = np.minimum(np.hypot(*velocity[i].T), np.hypot(*velocity[j].T))
    return offset, relative, slower


def _gather(column: NDArray[Any], slot: IntArray, found: NDArray[np.bool_], fill: float) -> NDArray[Any]:
    """``column[slot]`` where ``found``, ``fill`` elsewhere (``column`` may be empty)."""
    out = np.full((len(slot), *column.shape[1:]), fill, dtype=column.dtype)
    out[found] = column[slot[found]]
    return out


class DistanceMonitor:
    """Turns per-tick positions (and optionally velocities) into ``DistanceViolation`` start and
    end events (rules above).

    ``release_margin_m`` is the distance hysteresis; ``walk_speed_mps``, ``walk_tolerance_mps``,
    ``walk_grace_s``, ``velocity_smoothing_s`` and ``walk_drift_m`` say what walking together
    means (the defaults are tuned on the simulated demo crowd: walkers at 1.25 ± 0.2 m/s).

    >>> from bevflow.site import Thresholds
    >>> m = DistanceMonitor(Thresholds(violation_min_duration_s=1.0))
    >>> [len(m.update(t * 500_000_000, [1, 2], [[0, 0], [1, 0]])) for t in range(4)]
    [0, 0, 1, 0]
    >>> m.current_pairs.tolist()
    [[1, 2]]
    """

    def __init__(
        self,
        thresholds: Thresholds,
        zones: Sequence[Zone] = (),
        release_margin_m: float = 0.2,
        walk_speed_mps: float = 0.5,
        walk_tolerance_mps: float = 0.5,
        walk_grace_s: float = 1.0,
        velocity_smoothing_s: float = 0.5,
        walk_drift_m: float = 1.5,
    ) -> None:
        for name, value in (
            ("release_margin_m", release_margin_m),
            ("walk_speed_mps", walk_speed_mps),
            ("walk_tolerance_mps", walk_tolerance_mps),
            ("walk_grace_s", walk_grace_s),
            ("velocity_smoothing_s", velocity_smoothing_s),
            ("walk_drift_m", walk_drift_m),
        ):
            if not value >= 0:
                raise ValueError(f"{name} must be >= 0, got {value}")
        self.limit_m = float(thresholds.social_distance_m)
        self.release_m = self.limit_m + float(release_margin_m)
        self.min_duration_ns = seconds_to_ns(thresholds.violation_min_duration_s)
        self.group_after_ns = None if thresholds.group_after_s is None else seconds_to_ns(thresholds.group_after_s)
        self.group_walk_ns = None if thresholds.group_walk_s is None else seconds_to_ns(thresholds.group_walk_s)
        self.walk_speed_mps = float(walk_speed_mps)
        self.walk_tolerance_mps = float(walk_tolerance_mps)
        self.walk_grace_ns = seconds_to_ns(walk_grace_s)
        self.smoothing_s = float(velocity_smoothing_s)
        self.walk_drift_m = float(walk_drift_m)
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

    @property
    def walking_pairs(self) -> IntArray:
        """(K, 2) close track-id pairs walking together now, not (yet) a group: their violation
        waits while they keep walking together."""
        pairs = self._pairs
        return pair_ids(pairs.key[(pairs.state != GROUP) & self._walking(pairs, self._clock.last_ns or 0)])

    def reset(self) -> None:
        """Forget every pair and the clock, without publishing anything."""
        self._pairs = _Pairs.empty()
        self._clock = Clock()

    def update(
        self, time_ns: int, ids: ArrayLike, xy: ArrayLike, velocity: ArrayLike | None = None
    ) -> list[DistanceViolation]:
        """Advance to ``time_ns`` with the tracks present now, their feet positions and, when
        known, their (N, 2) velocities in m/s; returns the events that started or ended at this
        tick (ends first)."""
        ids_arr, xy_arr = check_positions(ids, xy)
        vel = None if velocity is None else _check_velocity(velocity, len(ids_arr))
        previous_ns = self._clock.last_ns
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
        was, slot, i, j = known[rows], slot[rows], i[rows], j[rows]
        dist, mid = dist[rows], (xy_arr[i] + xy_arr[j]) / 2.0
        prev_d = _gather(old.min_d, slot, was, np.inf)
        nearer = dist < prev_d
        pairs = _Pairs(
            key=key[rows],
            state=_gather(old.state, slot, was, CLOSE),
            first_ns=_gather(old.first_ns, slot, was, t),
            min_d=np.where(nearer, dist, prev_d),
            min_xy=np.where(nearer[:, None], mid, _gather(old.min_xy, slot, was, 0.0)),
            rel_v=_gather(old.rel_v, slot, was, 0.0),
            walk_from_ns=_gather(old.walk_from_ns, slot, was, NO_WALK),
            walk_last_ns=_gather(old.walk_last_ns, slot, was, NO_WALK),
            walk_anchor=_gather(old.walk_anchor, slot, was, 0.0),
        )
        if vel is not None and self.group_walk_ns is not None:
            dt_s = 0.0 if previous_ns is None else (t - previous_ns) / NS_PER_S
            self._walk(pairs, t, was, dt_s, *_relative_motion(ids_arr, xy_arr, vel, i, j))
        pairs = _Pairs.concat(pairs, old.take(apart))
        grouped, started = self._promote(pairs, t)
        self._pairs = pairs
        return self._events([(ended, t, False), (grouped, t, True), (started, None, False)], t)

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

    def _walk(
        self, pairs: _Pairs, t: int, was: NDArray[np.bool_], dt_s: float, offset: FloatArray, relative: FloatArray,
        slower: FloatArray,
    ) -> None:
        """Smooth each pair's relative velocity and extend, start or end its walking-together
        stretch, in place. ``offset`` and ``relative`` are the position and velocity of the larger
        id relative to the smaller, ``slower`` the speed of the slower of the two."""
        # Exponential smoothing over the tick interval: a step aside or a noisy estimate moves it
        # little, a real change of course (one of them stops) within about the smoothing time.
        keep = np.exp(-dt_s / self.smoothing_s) if self.smoothing_s > 0 else 0.0
        pairs.rel_v[:] = np.where(was[:, None], keep * pairs.rel_v + (1.0 - keep) * relative, relative)
        together = (slower >= self.walk_speed_mps) & (np.hypot(*pairs.rel_v.T) <= self.walk_tolerance_mps)
        going = self._walking(pairs, t)
        # Similar velocities still let one overtake the other slowly; a group keeps its formation,
        # so a stretch whose offset wandered too far from where it began ends at once.
        drifted = going & (np.hypot(*(offset - pairs.walk_anchor).T) > self.walk_drift_m)
        pairs.walk_from_ns[drifted | ~going] = NO_WALK
        start = together & ~drifted & (pairs.walk_from_ns == NO_WALK)
        pairs.walk_from_ns[start] = t
        pairs.walk_anchor[start] = offset[start]
        pairs.walk_last_ns[together & ~drifted] = t

    def _walking(self, pairs: _Pairs, t: int) -> NDArray[np.bool_]:
        """Pairs whose walking-together stretch is still going at ``t`` (within the grace)."""
        walking: NDArray[np.bool_] = (pairs.walk_from_ns != NO_WALK) & (t - pairs.walk_last_ns <= self.walk_grace_ns)
        return walking

    def _promote(self, pairs: _Pairs, t: int) -> tuple[_Pairs, _Pairs]:
        """Promote the pairs close long enough, or walking together long enough, in place; returns
        the violations closed by becoming groups and the violations that start now."""
        age = t - pairs.first_ns
        walking = self._walking(pairs, t)
        long_close = age >= self.group_after_ns if self.group_after_ns is not None else np.zeros(len(age), bool)
        walked = pairs.walk_last_ns - pairs.walk_from_ns
        long_walk = walking & (walked >= self.group_walk_ns) if self.group_walk_ns is not None else False
        to_group = (pairs.state != GROUP) & (long_close | long_walk)
        to_violation = (pairs.state == CLOSE) & (age >= self.min_duration_ns) & ~to_group & ~walking
        grouped = pairs.take(np.flatnonzero(to_group & (pairs.state == VIOLATION)))
        pairs.state[to_group] = GROUP
        pairs.state[to_violation] = VIOLATION
        return grouped, pairs.take(np.flatnonzero(to_violation))

    def _events(self, batches: list[tuple[_Pairs, int | None, bool]], t: int) -> list[DistanceViolation]:
        """Messages raised at ``t`` for batches of (pairs, end_ns, group), with one zone look-up for
        them all."""
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
                    raised_ns=t,
                )
                for (lo, hi), start, d, (x, y) in rows
            ]
        return events
